"""A place's rings: how the surface around it bends, read the way a touch reads it.

A touch's curves leave the contact in a few directions along the surface (Section 2: planar
sections through the contact that hold the normal).  At an arc length ``s`` along each, the curve
lies a height ``h(s, theta)`` over the tangent plane.  Per arc, ``h / s`` in the direction's angle
``theta`` is fitted by ``a + b cos 2 theta + c sin 2 theta``:

- the *ring mean* ``a(s)``, how far the surface falls away from (or rises to) the tangent plane on
  average, and the *ring amplitude* ``|(b, c)|(s)``, how unequally it bends across directions,
  change with neither the turn of the touch about its normal nor (to first order) a tilt of its
  estimated normal: a tilt adds ``s sin(tilt) cos(theta - phi)``, which cancels between a curve's
  two halves and is orthogonal to the fit's basis;
- at small ``s``, ``2 a / s`` is the mean curvature and ``4 |(b, c)| / s`` the curvatures' gap; at
  larger ``s`` they tell a flat face beside an edge from a flat face, a groove from a bump.

A mesh's places (its vertices thinned to one a cell :data:`CELL_MM` across) are read on
:data:`ANGLES` sections each (:func:`tactrec.surfaces.section_walk.section_heights`) at the arcs
:data:`ARCS_MM`, in millimetres whatever the model's units, so that the features of models in
different units and of a touch compare.  A touch is read at the arcs its curves reach; a patch's
spokes only at those every half of them reaches, since a map's rows and columns outreach its
diagonals and a ring read in some directions alone does not fix its harmonic.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..linalg import dot3, lstsq, norm3
from .mesh_grid import first_per_cell
from ..units import conversion

__all__ = ["PlaceRings", "model_rings", "touch_rings", "touch_ring_noise", "ARCS_MM", "ANGLES", "CELL_MM", "FEATURES",
           "ENDED"]

#: arc lengths (mm) the rings are read at: a P3 touch's curves reach 12 mm each way
ARCS_MM = (3.0, 6.0, 9.0, 11.0)
#: sections a place is read on, equally spaced: a touch's three curves 60 degrees apart are six
#: directions, and a mean over twelve leaves only the twelfth harmonic
ANGLES = 12
#: a place is the first vertex of each grid cell this many millimetres across: about a field tier's
#: cell for a 12 mm touch (``screen_step`` x its radius), where the screen's turns reach between places
CELL_MM = 2.0
#: features per place: the ring means, then the ring amplitudes, one per arc
FEATURES = 2 * len(ARCS_MM)
#: the feature of a ring whose sections end (the mesh's boundary) before its arc in more than half
#: the directions: unlike any touch's (whose ``|h / s|`` is at most 1)
ENDED = 10.0


@dataclasses.dataclass(frozen=True)
class PlaceRings:
    """A mesh's places ``(P,)`` (vertex indices) and their rings, ``features (P, FEATURES)`` float32."""

    places: np.ndarray
    features: np.ndarray

    def to_store(self) -> dict[str, np.ndarray]:
        return {"rings_places": self.places, "rings_features": self.features}

    @classmethod
    def from_store(cls, arrays, vertices: int) -> "PlaceRings | None":
        """The stored rings, or None where the store has none; ValueError where they are malformed."""
        if "rings_places" not in arrays:
            return None
        places = np.asarray(arrays["rings_places"], dtype=np.int64)
        features = np.asarray(arrays["rings_features"], dtype=np.float32)
        if places.ndim != 1 or features.shape != (len(places), FEATURES) or \
                (len(places) and (places.min() < 0 or places.max() >= vertices)) or not np.all(np.isfinite(features)):
            raise ValueError("the stored rings do not match the mesh")
        return cls(places, features)


def _fit(theta: np.ndarray, values: np.ndarray) -> tuple[float, float]:
    """``a`` and ``|(b, c)|`` of ``a + b cos 2 theta + c sin 2 theta`` fitted to ``values``; NaN where
    the directions do not determine them."""
    coef, rank = lstsq(_basis(theta), values)
    if rank < 3:
        return np.nan, np.nan
    return float(coef[0]), float(np.hypot(coef[1], coef[2]))


def _basis(theta: np.ndarray) -> np.ndarray:
    """The ring's fit's basis at directions ``theta``: ``1, cos 2 theta, sin 2 theta`` ``(n, 3)``."""
    return np.stack([np.ones_like(theta), np.cos(2.0 * theta), np.sin(2.0 * theta)], axis=1)


def ring_features(ratios: np.ndarray) -> np.ndarray:
    """Features ``(P, FEATURES)`` of ``h / s`` read on :data:`ANGLES` equal directions ``(P, ANGLES, J)``:
    each arc's mean over the directions and the amplitude of its ``cos 2 theta`` harmonic
    (:data:`ENDED` where more than half the directions ended before the arc)."""
    theta = np.arange(ANGLES) * (2.0 * np.pi / ANGLES)
    present = np.isfinite(ratios)
    count = present.sum(axis=1)
    r = np.where(present, ratios, 0.0)
    mean = r.sum(axis=1) / np.maximum(count, 1)
    b = 2.0 * np.sum(r * np.cos(2.0 * theta)[None, :, None], axis=1) / np.maximum(count, 1)
    c = 2.0 * np.sum(r * np.sin(2.0 * theta)[None, :, None], axis=1) / np.maximum(count, 1)
    out = np.concatenate([mean, np.hypot(b, c)], axis=1)
    ended = np.concatenate([count, count], axis=1) * 2 <= ANGLES
    return np.where(ended, ENDED, out).astype(np.float32)


def model_rings(model) -> PlaceRings:
    """The places of a mesh ``model`` and their rings (module text)."""
    from .section_walk import section_heights          # numba: only once a model's rings are made

    mm = conversion("mm", model.units)                      # millimetres to the model's units
    places = first_per_cell(model, np.arange(len(model.vertices)), CELL_MM * mm)
    field = model.fine_curvatures
    n, u = field.normal[places], field.d1[places]
    v = np.cross(n, u)
    theta = np.arange(ANGLES) * (2.0 * np.pi / ANGLES)
    directions = np.cos(theta)[None, :, None] * u[:, None] + np.sin(theta)[None, :, None] * v[:, None]
    arcs = np.asarray(ARCS_MM) * mm
    heights = section_heights(model, places, n, directions, arcs)
    return PlaceRings(places.astype(np.int64), ring_features(heights / arcs))


def touch_rings(touch, sign: int) -> np.ndarray:
    """The rings of ``touch`` (:class:`~tactrec.features.Touch`) with its normal as estimated (``sign``
    1) or reversed (-1): ``(FEATURES,)``, NaN at the arcs its curves do not reach in at least three
    directions that fix the fit."""
    out = np.full(FEATURES, np.nan)
    for j, (theta, values) in enumerate(_touch_samples(touch, sign)):
        if len(values) >= 3:
            out[j], out[len(ARCS_MM) + j] = _fit(theta, values)
    return out


def touch_ring_noise(touch, sign: int) -> float:
    """How far the touch's noise moves its rings (:func:`touch_rings`): the root of the summed
    variances of its features, from each height's noise (the touch's own ``sigma``, millimetres)
    through the fit of each arc, contact and normal held (a first-order bound on a draw's
    distance from the noise-free rings)."""
    sigma = float(touch.noise) * conversion(touch.data.units, "mm")
    total = 0.0
    for j, (theta, values) in enumerate(_touch_samples(touch, sign)):
        if len(values) < 3:
            continue
        basis = _basis(theta)
        gram = basis.T @ basis
        if np.linalg.matrix_rank(gram) < 3:
            continue
        cov = (sigma / ARCS_MM[j]) ** 2 * np.linalg.inv(gram)
        total += cov[0, 0] + max(cov[1, 1], cov[2, 2])
    return float(np.sqrt(total))


def _touch_samples(touch, sign: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per arc of :data:`ARCS_MM`, the directions and ``h / s`` of the touch's curves at that arc from
    the contact (each half of each curve that reaches it; of a patch's spokes, none where some half
    does not)."""
    t = touch.in_units(conversion(touch.data.units, "mm"))
    s = t.on_surface(sign)
    g = s.geometry if s is not t else t.oriented(sign)
    c, n = g.contact, g.normal
    first = g.tangents[0] - dot3(g.tangents[0], n) * n
    first = first / norm3(first)
    second = np.cross(n, first)
    rays = []                                           # each half of each curve, from the contact out
    for curve in s.curves:
        curve = np.asarray(curve, dtype=np.float64)
        k0 = int(np.argmin(norm3(curve - c)))
        for half in (curve[k0:], curve[k0::-1]):
            if len(half) < 2:
                continue
            arc = np.concatenate([[0.0], np.cumsum(norm3(np.diff(half, axis=0)))])
            arc += norm3(half[0] - c)
            rays.append((half, arc))
    even = min((arc[-1] for _, arc in rays), default=0.0) if touch.data.patch is not None else np.inf
    out = []
    for s_mm in ARCS_MM:
        theta, values = [], []
        for half, arc in rays:
            if arc[-1] < s_mm or s_mm > even:
                continue
            x = np.array([np.interp(s_mm, arc, half[:, i]) for i in range(3)]) - c
            h = float(dot3(x, n))
            flat = x - h * n
            theta.append(np.arctan2(dot3(flat, second), dot3(flat, first)))
            values.append(h / s_mm)
        out.append((np.array(theta), np.array(values)))
    return out
