"""The centres of a round tip: the data moved onto the surface, and the surface offset by the tip.

A probe with a spherical tip of radius ``r`` records the tip's *centres*.
A centre lies on the surface offset outward by ``r``: its closest surface
point is the contact, at distance ``r``, along the surface's outward normal
there.  A touch's ``tip_radius`` (:class:`tactrec.io.touch.TactileData`) is
that ``r``; tactrec handles it by one rule:

(a) **the search works on the data moved onto the surface.**  Every stage
    that reads the data's local shape or a model's truncated distance field
    (the curvature lookup and the places, the field screen and its field
    steps, a closed-form surface's table rows and first turn) takes each
    centre ``x_i`` moved to ``x_i - r n_i`` (:func:`surface_curves`), ``n_i``
    the outward normal of the offset surface at ``x_i`` as the data's own
    local fit gives it: the estimate's curvature tensor at the contact
    (its normal tilts by ``-S (x_i - p)``, ``S`` the shape operator) made
    perpendicular to the curve's own tangent at ``x_i`` (a polynomial in arc
    length along the curve), so the curve's own bend is followed exactly and
    only the tilt across its plane is the tensor's.  At the contact this is
    the offset correction of the estimate (:func:`corrected`): the contact
    moves by ``-r N`` and each principal curvature (convex negative, outward
    ``N``) becomes ``kappa / (1 + r kappa)``; offset surfaces share their
    normals and principal directions.  A field lookup beyond the band of a
    mesh's truncated field (about 1.4 mean edges, :mod:`tactrec.surfaces.mesh_field`)
    returns the truncation, so the centres themselves, ``r`` off the
    surface, could not be screened on it.

(b) **every exact distance is measured from the raw centres against the
    offset surface**: the signed distance minus ``r`` (:class:`Offset`).
    Every Gauss-Newton step on exact distances (from the first exact step
    after the screen to the final polish), the reported error, the
    probabilities' residuals and a session's joint fits and fit tests use
    it, so the final registration is exact whatever (a) left.  A mesh's
    signed distance is exact; a closed-form surface's first-order distance
    ``f / |grad f|`` (eq. 11) is off by about ``r^2 kappa / 2`` at the
    centres, so its offset measures the distance to the foot point
    (:func:`foot_distance`): the offset of the implicit surface.

Which side is outside: the normal a touch is tried with (``outward``, or
both without it) is the model's outward normal under the registration, so
each side moves the centres against its own normal, and the offset is the
same on both (the centres are always outside).

Where ``1 + r kappa <= 0`` the centres bend (convex, radius ``<= r``) more
tightly than a tip can follow any surface.  Exactly ``1 + r kappa = 0`` is
a sharp convex edge: the centres circle it at the radius ``r``, and the
estimate scatters about that value.  So a bend up to :data:`EDGE` tighter
(``1 + r kappa > -EDGE``, a bend radius above ``r / (1 + EDGE)``)
is read as such an edge, its ``1 + r kappa`` taken as :data:`SHARP` (a
surface radius of ``SHARP r``).  A tighter bend is not a guess where the
curves themselves show it: where a curve's own normal curvature at the
contact (what the data measure directly) is beyond ``-EDGE``, that side is
not tried.  A principal curvature beyond it, where no curve's is, is the
estimate's extrapolation (Euler's formula fitted to the curves' normal
curvatures overshoots at a kink of the centres' path, where a tip leaves
one face for another) and is read as an edge's like the rest.  A touch with
no side left is an
:class:`~tactrec.errors.InputError` naming its file
(:meth:`tactrec.features.Touch.with_estimate`).

With ``r = 0`` nothing here runs: the touch and the models are used as they
are.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .estimation import LocalGeometry

__all__ = ["EDGE", "SHARP", "corrected", "surface_normals", "surface_curves", "Offset", "offset", "foot_distance",
           "FOOT_STEPS"]

#: tangent-plane steps of :func:`foot_distance` (each one implicit evaluation; the tangential error
#: shrinks by about ``r |kappa|`` a step)
FOOT_STEPS = 12
#: a bend of the centres this much tighter than the tip (in ``1 + r kappa``) is a sharp edge's, within
#: the estimate's error; beyond it, no surface gives the data
EDGE = 0.25
#: the ``1 + r kappa`` a sharp edge's bend is given (the surface's radius there, over ``r``)
SHARP = 0.05
#: highest degree of the polynomial in arc length that gives a curve's tangent at each point
TANGENT_DEGREE = 6


def corrected(geometry: LocalGeometry, r: float) -> LocalGeometry | None:
    """The surface's estimate at the contact from the offset data's ``geometry`` (normal as the side
    to try: the outward one): contact moved by ``-r N``, ``kappa -> kappa / (1 + r kappa)`` for the
    principal curvatures (and, by Euler's theorem, the normal curvatures along the tangents);
    directions, tangents and normal kept.  ``1 + r kappa`` below :data:`SHARP` but above ``-EDGE`` is
    a sharp edge's (taken as :data:`SHARP`); None where a curve's own normal curvature is at or below
    ``-EDGE`` (module text)."""
    if 1.0 + r * float(np.min(geometry.normal_curvatures)) <= -EDGE:       # the tightest bend measured
        return None
    k1, k2 = (max(k, -1.0 / r) / max(1.0 + r * k, SHARP) for k in (geometry.k1, geometry.k2))   # an edge: -1/(SHARP r)
    c = np.sum(geometry.tangents * geometry.directions[0], axis=1)
    s = np.sum(geometry.tangents * geometry.directions[1], axis=1)
    kn = (k1 * c * c + k2 * s * s) / (c * c + s * s)
    return dataclasses.replace(geometry, contact=geometry.contact - r * geometry.normal, k1=float(k1),
                               k2=float(k2), normal_curvatures=kn)


def _tangents(curve: np.ndarray) -> np.ndarray:
    """Unit tangents ``(n, 3)`` of a curve ``(n, 3)``: a least-squares polynomial in arc length (degree
    up to :data:`TANGENT_DEGREE`, a quarter of the points) per coordinate, differentiated."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
    half = 0.5 * (s[-1] - s[0]) or 1.0
    u = (s - 0.5 * (s[-1] + s[0])) / half
    degree = int(max(2, min(TANGENT_DEGREE, (len(curve) - 1) // 4)))
    V = np.polynomial.legendre.legvander(u, degree)
    coef, *_ = np.linalg.lstsq(V, curve, rcond=None)                       # (degree + 1, 3)
    d = np.polynomial.legendre.legder(coef, axis=0)
    T = np.sum(np.polynomial.legendre.legvander(u, degree - 1)[:, :, None] * d[None], axis=1)   # element-wise
    return T / np.linalg.norm(T, axis=1, keepdims=True)


def surface_normals(curves, geometry: LocalGeometry) -> list[np.ndarray]:
    """The offset surface's outward normal at every data point (module text, (a)): ``(n_i, 3)`` per
    curve, on the side of ``geometry.normal``; ``geometry`` is the offset data's own estimate."""
    N, (d1, d2) = geometry.normal, geometry.directions
    out = []
    for curve in curves:
        x = np.asarray(curve, dtype=np.float64)
        rel = x - geometry.contact
        a, b = np.sum(rel * d1, axis=1), np.sum(rel * d2, axis=1)                      # element-wise: no BLAS
        m = N[None] - geometry.k1 * a[:, None] * d1[None] - geometry.k2 * b[:, None] * d2[None]
        T = _tangents(x)
        n = m - np.sum(m * T, axis=1, keepdims=True) * T
        out.append(n / np.linalg.norm(n, axis=1, keepdims=True))
    return out


def surface_curves(curves, geometry: LocalGeometry, r: float, sign: int) -> tuple[np.ndarray, ...]:
    """The centres ``curves`` moved onto the surface on side ``sign`` (1: the side of
    ``geometry.normal``, -1: the other): ``x_i - r sign n_i`` (:func:`surface_normals`)."""
    return tuple(np.asarray(c, dtype=np.float64) - (r * sign) * n
                 for c, n in zip(curves, surface_normals(curves, geometry)))


def foot_distance(model, points: np.ndarray, steps: int = FOOT_STEPS) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances ``(...)`` of ``points (..., 3)`` to a closed-form surface (positive outside)
    and the unit normals ``(..., 3)`` at their foot points: from each point, ``steps`` projections
    onto the tangent plane at the current foot estimate (``q <- x - ((x - q') . n) n``, ``q' = q -
    (f / |grad f|) n``), whose fixed point ``q`` has ``x - q`` along the normal at ``q``; then one
    Newton step onto ``f = 0``.  Not finite where ``grad f`` vanishes."""
    x = np.asarray(points, dtype=np.float64)
    q = x
    with np.errstate(all="ignore"):
        for _ in range(steps):
            fg = model.implicit(q, order=1)
            norm = np.sqrt(np.sum(fg[..., 1:] * fg[..., 1:], axis=-1))
            n = fg[..., 1:] / norm[..., None]
            on = q - (fg[..., 0] / norm)[..., None] * n
            q = x - np.sum((x - on) * n, axis=-1)[..., None] * n
        fg = model.implicit(q, order=1)
        norm = np.sqrt(np.sum(fg[..., 1:] * fg[..., 1:], axis=-1))
        n = fg[..., 1:] / norm[..., None]
        q = q - (fg[..., 0] / norm)[..., None] * n
        return np.sum((x - q) * n, axis=-1), n


class Offset:
    """A surface model offset outward by ``radius`` (module text, (b)): :meth:`planes` and
    :meth:`distance` measure the signed distance minus the radius, against the planes of the
    wrapped model at the closest (foot) points; everything else is the wrapped model's.

    ``radius`` is one number, or one per point ``(m,)`` for calls on ``m`` points at a time
    (``(..., m, 3)``, or ``(h * m, 3)`` flattened point-fastest), as a session's touches of
    different tips are measured together."""

    def __init__(self, model, radius):
        self.model = model
        r = np.asarray(radius, dtype=np.float64)
        self.radius = float(r) if r.ndim == 0 else r

    def __getattr__(self, name):
        if name == "model":                       # not yet set (a copy being made): no recursion
            raise AttributeError(name)
        return getattr(self.model, name)

    def _less(self, d: np.ndarray) -> np.ndarray:
        r = self.radius
        if isinstance(r, float):
            return d - r
        return (d.reshape(-1, len(r)) - r).reshape(d.shape)

    def planes(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances minus the radius ``(...)`` and the planes' unit normals ``(..., 3)``."""
        if self.model.kind == "mesh":
            d, n = self.model.planes(points)
        else:
            d, n = foot_distance(self.model, points)
        return self._less(np.asarray(d, dtype=np.float64)), n

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distances ``(...)`` of ``points (..., 3)`` to the offset surface."""
        return np.abs(self.planes(points)[0])

    def __repr__(self) -> str:
        return f"Offset({self.model!r}, {self.radius!r})"


def offset(model, radius):
    """``model`` itself where every radius is 0, else :class:`Offset` (one radius where all agree)."""
    r = np.asarray(radius, dtype=np.float64)
    if not np.any(r):
        return model
    if r.ndim and np.all(r == r.flat[0]):
        r = r.flat[0]
    return Offset(model, r)
