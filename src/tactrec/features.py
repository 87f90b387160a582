"""What recognition needs of one touch, computed once (paper Section 3.1).

:class:`Touch` holds the data points, the estimate at the contact
(:func:`tactrec.estimation.estimate`), the orientations of the normal to try
(one with an ``outward`` hint, both without), the data's noise and the
touch's radius.  :meth:`Touch.in_units` gives the same touch in a model's
units, once per unit scale.
"""

from __future__ import annotations

import dataclasses
from functools import cached_property

import numpy as np

from .errors import InputError
from .estimation import LocalGeometry, estimate, noise_level
from .io.touch import TactileData

__all__ = ["Touch", "subset"]


def subset(curves, per_curve: int) -> np.ndarray:
    """``per_curve`` points of each curve, evenly spread along it (ends included): ``(k * per_curve, 3)``."""
    return np.concatenate([np.asarray(c, dtype=np.float64)[np.linspace(0, len(c) - 1, per_curve).round().astype(int)]
                           for c in curves])


@dataclasses.dataclass(frozen=True)
class Touch:
    """One touch, ready for every model.

    Attributes
    ----------
    data : TactileData
        The touch as read (data units).
    estimate : LocalGeometry
        Contact, normal and principal curvatures (eqs. 1-6).
    scale : float
        Factor from data units to the units of this copy (1 for the data's own).
    noise : float
        The data's noise sigma per coordinate (third differences, median over the curves), data units.
    context : tuple of (n_i, 3) arrays
        Curves of other touches of the same object in the same frame (data units): a pose is
        scored on them too (:attr:`joint_points`), while the local geometry, the places and the
        noise come from this touch alone.
    fit : float
        With a context: the mean distance over all its points (data units) that its caller counts
        as a fit of the touch and the context together (0: the touch's own fit limit decides).
    """

    data: TactileData
    estimate: LocalGeometry
    scale: float = 1.0
    noise: float = 0.0
    context: tuple = ()
    fit: float = 0.0

    @classmethod
    def from_data(cls, data: TactileData, *, window: int | str | None = "auto", degree: int = 3,
                  curvature_method: str = "auto") -> "Touch":
        if data.tip_radius > 0:
            raise InputError(f"tip_radius {data.tip_radius:g}: tactrec does not register the centres of a round tip "
                             "yet; give points on the surface (tip_radius 0)", data.source)
        geometry = estimate(data, window=window, degree=degree, method=curvature_method)
        noise = float(np.median([noise_level(np.asarray(c, dtype=np.float64)) for c in data.curves]))
        return cls(data, geometry, 1.0, noise)

    @cached_property
    def curves(self) -> tuple[np.ndarray, ...]:
        """The curves, ``(n_i, 3)`` each, in this copy's units."""
        return tuple(np.asarray(c, dtype=np.float64) * self.scale for c in self.data.curves)

    @cached_property
    def points(self) -> np.ndarray:
        """All points ``(m, 3)``, in this copy's units."""
        return np.concatenate(self.curves)

    @cached_property
    def joint_curves(self) -> tuple[np.ndarray, ...]:
        """This touch's curves and then the context's, this copy's units."""
        return self.curves + tuple(np.asarray(c, dtype=np.float64) * self.scale for c in self.context)

    @cached_property
    def joint_points(self) -> np.ndarray:
        """All points of :attr:`joint_curves` ``(m, 3)``: what a pose is scored on."""
        return np.concatenate(self.joint_curves)

    @cached_property
    def joint_reach(self) -> float:
        """The largest distance of a joint point from their centroid, this copy's units."""
        x = self.joint_points
        return float(np.max(np.linalg.norm(x - x.mean(axis=0), axis=1)))

    def joint_subset(self, per_curve: int) -> np.ndarray:
        """:func:`subset` of the joint curves."""
        return subset(self.joint_curves, per_curve)

    def screen_subset(self, per_curve: int) -> np.ndarray:
        """The points a search's first screen scores every pose on: ``per_curve`` of each of this
        touch's curves (:func:`subset`) and the middle point of each context curve, this copy's
        units.  The screen then costs about what the touch alone costs, however many touches the
        context holds; the poses it keeps are scored on :meth:`joint_subset`."""
        context = self.joint_curves[len(self.curves):]
        return np.concatenate([self.subset(per_curve), *(c[len(c) // 2][None] for c in context)])

    def with_context(self, curves, *, fit: float = 0.0) -> "Touch":
        """The same touch, its poses scored also on ``curves`` (other touches, same frame, data units);
        ``fit``: the joint mean distance that counts as a fit of them all (see :attr:`fit`)."""
        return dataclasses.replace(self, context=tuple(np.asarray(c, dtype=np.float64) for c in curves),
                                   fit=float(fit))

    @cached_property
    def geometry(self) -> LocalGeometry:
        """The estimate in this copy's units."""
        g, s = self.estimate, self.scale
        if s == 1.0:
            return g
        return dataclasses.replace(g, contact=g.contact * s, k1=g.k1 / s, k2=g.k2 / s,
                                   normal_curvatures=g.normal_curvatures / s)

    @cached_property
    def orientations(self) -> tuple[LocalGeometry, ...]:
        """The estimates to try: the normal as oriented by ``outward``, or both normals."""
        g = self.geometry
        return (g,) if g.oriented else (g, g.flipped())

    def oriented(self, sign: int) -> LocalGeometry:
        """The estimate with the normal as estimated (``sign`` 1) or reversed (-1)."""
        return self.orientations[0] if sign == 1 else self.geometry.flipped()

    @cached_property
    def radius(self) -> float:
        """The largest distance of a data point from the contact, this copy's units."""
        return float(np.max(np.linalg.norm(self.points - self.geometry.contact, axis=1)))

    @cached_property
    def reach(self) -> float:
        """The largest distance of a data point from the points' centroid, this copy's units."""
        return float(np.max(np.linalg.norm(self.points - self.points.mean(axis=0), axis=1)))

    @cached_property
    def key(self) -> str:
        """A digest of the touch's own points, the estimate and the scale: names what depends on the
        touch alone in caches (its places on a model: a context plays no part in them)."""
        import hashlib

        h = hashlib.sha1(np.ascontiguousarray(self.points).tobytes())
        h.update(np.ascontiguousarray(self.geometry.normal).tobytes())
        h.update(np.float64(self.scale).tobytes())
        return h.hexdigest()

    @property
    def sigma(self) -> float:
        """The noise sigma in this copy's units."""
        return self.noise * self.scale

    def subset(self, per_curve: int) -> np.ndarray:
        """:func:`subset` of this copy's curves."""
        return subset(self.curves, per_curve)

    def in_units(self, scale: float) -> "Touch":
        """The same touch with coordinates multiplied by ``scale`` (data to model units)."""
        if scale == self.scale:
            return self
        return dataclasses.replace(self, scale=float(scale))          # every other field kept, nothing cached
