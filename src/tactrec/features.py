"""What recognition needs of one touch, computed once (paper Section 3.1).

:class:`Touch` holds the data points, the estimate at the contact
(:func:`tactrec.estimation.estimate`), the orientations of the normal to try
(one with an ``outward`` hint, both without), the data's noise and the
touch's radius.  :meth:`Touch.in_units` gives the same touch in a model's
units, once per unit scale.

A touch whose points are the centres of a round tip (``tip_radius`` > 0) is
handled by the one rule of :mod:`tactrec.tip`: its estimate is the surface's
(the contact moved by ``-r N``, each principal curvature ``kappa / (1 + r
kappa)``), the stages that read a mesh's places or distance field take its
centres as a touch of the mesh offset by the tip (:meth:`Touch.searched`; or
its points moved onto the surface, :meth:`Touch.on_surface`, one copy per
side of the normal tried), and every exact distance is measured from its
points, the centres, against the model offset by the tip
(:meth:`Touch.exact`).

Points a sensor recorded off its curve's trace (slips, spikes) are set aside
first (:mod:`tactrec.outliers`): everything here, the estimate, the noise,
the points every registration and probability measures, is of the points
kept.
"""

from __future__ import annotations

import dataclasses
from functools import cached_property

import numpy as np

from .errors import InputError
from .estimation import LocalGeometry, estimate, noise_level
from .estimation_patch import estimate_patch, patch_noise
from .io.touch import TactileData
from .outliers import kept
from .tip import EDGE, bends, corrected, offset, surface_curves, traceable

__all__ = ["Touch", "Context", "subset"]


def subset(curves, per_curve: int) -> np.ndarray:
    """``per_curve`` points of each curve, evenly spread along it (ends included): ``(k * per_curve, 3)``."""
    return np.concatenate([np.asarray(c, dtype=np.float64)[np.linspace(0, len(c) - 1, per_curve).round().astype(int)]
                           for c in curves])


@dataclasses.dataclass(frozen=True)
class Context:
    """Other touches of the same object, in the same frame, that a touch's poses are scored on too
    (a session's touches: :mod:`tactrec.session`).

    Attributes
    ----------
    curves : tuple of (n_i, 3) arrays
        Their curves (data units).
    fit : float
        The mean distance over the touch's points and these together (data units) that counts as
        a fit of them all (0: the touch's own fit limit decides).
    tips : tuple of float
        Each curve's tip radius (data units; empty: all 0).
    surface : tuple of (n_i, 3) arrays
        The curves moved onto the surface (data units; empty: the curves as given).
    """

    curves: tuple
    fit: float = 0.0
    tips: tuple = ()
    surface: tuple = ()


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
    tip : float
        The tip's radius (data units; 0: the points lie on the surface).
    sides_data : tuple of (sign, LocalGeometry, tuple of (n_i, 3) arrays)
        With a tip: per side of the normal to try (1: as estimated, -1: reversed), the surface's
        estimate (normal on that side) and the curves moved onto the surface, data units
        (:mod:`tactrec.tip`).
    context_tips : tuple of float
        The tip's radius of each context curve (data units; empty: all 0).
    context_surface : tuple of (n_i, 3) arrays
        The context curves moved onto the surface (data units; empty: the context as given).
    centres : LocalGeometry or None
        With a tip: the estimate of the centres themselves (data units), as the search of the
        surface offset by the tip takes it (:meth:`searched`).
    outliers : int
        How many of the points as read were set aside as off their curve's trace
        (:mod:`tactrec.outliers`); ``data`` holds the points kept.
    """

    data: TactileData
    estimate: LocalGeometry
    scale: float = 1.0
    noise: float = 0.0
    context: tuple = ()
    fit: float = 0.0
    tip: float = 0.0
    sides_data: tuple = ()
    context_tips: tuple = ()
    context_surface: tuple = ()
    outliers: int = 0
    centres: LocalGeometry | None = None

    @classmethod
    def from_data(cls, data: TactileData, *, window: int | str | None = "auto", degree: int = 3,
                  curvature_method: str = "auto") -> "Touch":
        """The touch of ``data``: its points off their curves' traces set aside (:mod:`tactrec.outliers`;
        an :class:`InputError` where too few are left), then the estimate and the noise of those kept."""
        if data.contacts is not None:              # contacts: no curvature, their stated noise
            return cls(data, contact_geometry(data.contacts), 1.0, data.contacts.noise)
        if data.patch is not None:                 # a patch: its own fit; its stated noise, or its own estimate
            noise = patch_noise(data.patch) if data.patch.point_sd is None else float(data.patch.point_sd)
            geometry = estimate_patch(data, noise)
            return cls(data, geometry, 1.0, noise).with_estimate(geometry)
        data, count = kept(data)
        geometry = estimate(data, window=window, degree=degree, method=curvature_method)
        noise = float(np.median([noise_level(np.asarray(c, dtype=np.float64)) for c in data.curves]))
        return cls(data, geometry, 1.0, noise, outliers=count).with_estimate(geometry)

    def with_estimate(self, geometry: LocalGeometry) -> "Touch":
        """The same touch with the estimate of its data ``geometry`` (data units): with a tip, the
        centres' estimate, corrected and the curves moved onto the surface per side
        (:mod:`tactrec.tip`).  An :class:`InputError` where no side can be traced by the tip."""
        data, tip = self.data, float(self.data.tip_radius)
        if not tip > 0:
            return dataclasses.replace(self, estimate=geometry)
        sides = []
        for sign in (1,) if geometry.oriented else (1, -1):
            side = geometry if sign == 1 else geometry.flipped()
            if traceable(data.curves, side, tip):
                sides.append((sign, corrected(side, tip), surface_curves(data.curves, geometry, tip, sign)))
        if not sides:
            kn = bends(data.curves, geometry)
            bend = 1.0 / (-np.min(kn) if geometry.oriented else max(-np.min(kn), np.max(kn)))
            raise InputError(f"tip_radius {tip:g}: the curves bend more tightly (radius {bend:.3g}) than a tip of "
                             f"that radius can trace any surface (a sharp edge's bend: {1 / (1 + EDGE):g} x the radius "
                             "or more)", data.source)
        sign, surface, _ = sides[0]
        return dataclasses.replace(self, estimate=surface if sign == 1 else surface.flipped(), tip=tip,
                                   sides_data=tuple(sides), centres=geometry)

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

    def with_context(self, context: Context) -> "Touch":
        """The same touch, its poses scored also on the curves of ``context`` (other touches, same
        frame): :attr:`context` and :attr:`fit` from it, the tips and surface curves where any tip
        is not 0."""
        tips = () if not context.tips or not np.any(context.tips) else tuple(float(r) for r in context.tips)
        surface = () if not tips or not context.surface else \
            tuple(np.asarray(c, dtype=np.float64) for c in context.surface)
        return dataclasses.replace(self, context=tuple(np.asarray(c, dtype=np.float64) for c in context.curves),
                                   fit=float(context.fit), context_tips=tips, context_surface=surface)

    @cached_property
    def geometry(self) -> LocalGeometry:
        """The estimate in this copy's units."""
        return _scaled(self.estimate, self.scale)

    @cached_property
    def sides(self) -> tuple[tuple[int, LocalGeometry], ...]:
        """The estimates to try, each with its side (1: the normal as estimated, -1: reversed), this
        copy's units: the normal as oriented by ``outward``, or both normals; with a tip, each the
        surface's estimate on its side, and only the sides a tip can trace."""
        if self.tip > 0:
            return tuple((sign, _scaled(g, self.scale)) for sign, g, _ in self.sides_data)
        g = self.geometry
        return ((1, g),) if g.oriented else ((1, g), (-1, g.flipped()))

    @property
    def orientations(self) -> tuple[LocalGeometry, ...]:
        """The estimates of :attr:`sides`."""
        return tuple(g for _, g in self.sides)

    def oriented(self, sign: int) -> LocalGeometry:
        """The estimate with the normal as estimated (``sign`` 1) or reversed (-1)."""
        if self.tip > 0:
            return dict(self.sides)[sign]
        return self.orientations[0] if sign == 1 else self.geometry.flipped()

    @cached_property
    def _surfaces(self) -> dict:
        return {}

    def on_surface(self, sign: int) -> "Touch":
        """The touch as the field and the local fits see it on side ``sign`` (:mod:`tactrec.tip`, (a)):
        its curves moved onto the surface, its estimate that side's (normal as tried), the context
        moved onto the surface, no tip.  The touch itself when neither it nor its context has a tip."""
        if not self.tip > 0 and not self.context_tips:
            return self
        if sign not in self._surfaces:
            if self.tip > 0:
                _, g, curves = next(side for side in self.sides_data if side[0] == sign)
            else:
                g, curves = self.estimate if sign == 1 else self.estimate.flipped(), self.data.curves
            data = dataclasses.replace(self.data, curves=curves, contact=g.contact, tip_radius=0.0)
            context = self.context_surface or self.context
            self._surfaces[sign] = dataclasses.replace(self, data=data, estimate=g, tip=0.0, sides_data=(),
                                                       context=context, context_tips=(), context_surface=())
        return self._surfaces[sign]

    def searched(self, model, sign: int) -> tuple:
        """What a search poses on side ``sign`` of a mesh ``model`` (:mod:`tactrec.tip`, (a)): the
        model as the search sees it, the touch whose points it poses there and that touch's estimate
        on the side (normal as tried).  Where every joint
        curve has one tip radius ``r`` > 0: the mesh offset by ``r``
        (:class:`tactrec.surfaces.mesh_offset.OffsetMesh`) and the centres themselves, with their
        own estimate (a plain touch of the offset surface); else the model and :meth:`on_surface`."""
        tips = self.joint_tips
        if model.kind == "mesh" and self.tip > 0 and np.all(tips == tips[0]):
            if "centres" not in self._surfaces:
                data = dataclasses.replace(self.data, tip_radius=0.0)
                self._surfaces["centres"] = dataclasses.replace(
                    self, data=data, estimate=self.centres, tip=0.0, sides_data=(), context_tips=(),
                    context_surface=())
            view = self._surfaces["centres"]
            return model.offset(float(tips[0])), view, view.oriented(sign)
        return model, self.on_surface(sign), self.oriented(sign)

    @cached_property
    def joint_tips(self) -> np.ndarray:
        """The tip's radius of each of :attr:`joint_curves` ``(k,)``, this copy's units."""
        context = self.context_tips or (0.0,) * len(self.context)
        return np.array((self.tip,) * len(self.curves) + tuple(context), dtype=np.float64) * self.scale

    def exact(self, model, per_curve: int | None = None, *, screen: bool = False):
        """What the exact distances of this copy's points are measured against (:mod:`tactrec.tip`, (b)):
        ``model`` offset by each point's tip (``model`` itself without one), for
        :attr:`joint_points` (``per_curve`` None), :meth:`joint_subset` or, with ``screen``,
        :meth:`screen_subset` of ``per_curve`` points a curve."""
        tips = self.joint_tips
        if not np.any(tips):
            return model
        if per_curve is None:
            radii = np.repeat(tips, [len(c) for c in self.joint_curves])
        elif screen:
            radii = np.concatenate([np.repeat(tips[:len(self.curves)], per_curve), tips[len(self.curves):]])
        else:
            radii = np.repeat(tips, per_curve)
        return offset(model, radii)

    @cached_property
    def radius(self) -> float:
        """The largest distance of a data point from the contact, this copy's units (with a tip, of a
        point moved onto the surface, on the first side tried)."""
        if self.tip > 0:
            return self.on_surface(self.sides[0][0]).radius
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
        if self.tip > 0:
            h.update(np.float64(self.tip).tobytes())
        return h.hexdigest()

    @cached_property
    def scales(self):
        """The data normal at several scales (:func:`tactrec.normal_scales.cone_normals`), finest first
        and the estimate's own (eq. 1, over its fit's window) last, this copy's units, oriented by the
        ``outward`` hint where given, else like the estimate's normal.  Where they disagree
        (:attr:`~tactrec.normal_scales.Scales.agree` False) the touch lies on a sharp, thin or folded
        place."""
        from .engine.screen import DISTINCT
        from .normal_scales import cone_normals

        g = self.geometry
        side = g.normal if self.data.outward is None else np.asarray(self.data.outward, dtype=np.float64)
        return cone_normals(self.curves, g.contact, side, sigma=self.sigma, distinct=DISTINCT, window=g.normal)

    def fine_normal(self, sign: int) -> np.ndarray | None:
        """The finest scale's normal (:attr:`scales`) on side ``sign`` (1: as oriented, -1: reversed);
        None where no chord is short enough."""
        normals = self.scales.normals
        return sign * normals[0] if len(normals) > 1 else None          # the last is the window's own

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


def contact_geometry(contacts) -> LocalGeometry:
    """What a touch of contacts gives of the local geometry: the contact nearest the contacts' centroid
    of those with a normal (the first of equals), its normal, and no curvature (NaN)."""
    x = contacts.points
    given = np.flatnonzero(contacts.has_normal)
    if not len(given):
        given = np.arange(len(x))
    i = int(given[np.argmin(np.linalg.norm(x[given] - x.mean(axis=0), axis=1))])
    n = contacts.normals[i] if contacts.has_normal[i] else np.array([0.0, 0.0, 1.0])
    from .registration.result import local_frame

    frame = local_frame(n)
    return LocalGeometry(x[i].copy(), frame[2], np.nan, np.nan, frame[:2], np.zeros((0, 3)), np.zeros(0),
                         bool(contacts.has_normal[i]))


def _scaled(g: LocalGeometry, s: float) -> LocalGeometry:
    """The estimate ``g`` with lengths multiplied by ``s``."""
    if s == 1.0:
        return g
    return dataclasses.replace(g, contact=g.contact * s, k1=g.k1 / s, k2=g.k2 / s,
                               normal_curvatures=g.normal_curvatures / s)
