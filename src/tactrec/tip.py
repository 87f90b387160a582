"""The centres of a round tip: the data moved onto the surface, and the surface offset by the tip.

A probe with a spherical tip of radius ``r`` records the tip's *centres*.
A centre lies on the surface offset outward by ``r``: its closest surface
point is the contact, at distance ``r``, along the surface's outward normal
there.  A touch's ``tip_radius`` (:class:`tactrec.io.touch.TactileData`) is
that ``r``; tactrec handles it by one rule:

(a) **the search of a mesh is a search of the offset surface.**  Every
    stage that reads a mesh's places, curvatures or truncated distance field
    (the curvature lookup and the places, the field screen and its field
    steps, the local grid) takes the centres as they are, with their own
    estimate, as a plain touch of the mesh offset by ``r``
    (:class:`tactrec.surfaces.mesh_offset.OffsetMesh`: each place lifted by
    ``r`` along its normal, each principal curvature ``kappa / (1 - r
    kappa)``, the field of the signed distance minus ``r``;
    :meth:`tactrec.features.Touch.searched`).  Nothing is moved along a normal
    the data do not give: far from the contact the data's own local fit
    tilts its normals by millimetres' worth, and at a sharp feature, where a
    tip's centres round the edge, the data normal is tens of degrees off.
    Where the touch and its context (a session's other touches) have
    different tips, and on closed-form surfaces (their table rows and first
    turn), these stages take each centre ``x_i`` moved to ``x_i - r n_i``
    (:func:`surface_curves`), ``n_i`` the outward normal of the offset
    surface at ``x_i`` as the data's own local fit gives it: the estimate's
    curvature tensor at the contact (its normal tilts by ``-S (x_i - p)``,
    ``S`` the shape operator) made perpendicular to the curve's own tangent
    at ``x_i`` (a polynomial in arc length along the curve).  At the contact
    this is the offset correction of the estimate (:func:`corrected`): the
    contact moves by ``-r N`` and each principal curvature (convex negative,
    outward ``N``) becomes ``kappa / (1 + r kappa)``; offset surfaces share
    their normals and principal directions.

(b) **every exact distance is measured from the raw centres against the
    offset surface**: the signed distance minus ``r``
    (:class:`tactrec.surfaces.offset.Offset`).
    Every Gauss-Newton step on exact distances (from the first exact step
    after the screen to the final polish), the reported error, the
    probabilities' residuals and a session's joint fits and fit tests use
    it, so the final registration is exact whatever (a) left.  A mesh's
    signed distance is exact; a closed-form surface's first-order distance
    ``f / |grad f|`` (eq. 11) is off by about ``r^2 kappa / 2`` at the
    centres, so its offset measures the distance to the foot point
    (:func:`tactrec.surfaces.offset.foot_distance`): the offset of the implicit surface.

Which side is outside: the normal a touch is tried with (``outward``, or
both without it) is the model's outward normal under the registration, so
each side moves the centres against its own normal, and the offset is the
same on both (the centres are always outside).

Where ``1 + r kappa <= 0`` the centres bend (convex, radius ``<= r``) more
tightly than a tip can follow any surface.  Exactly ``1 + r kappa = 0`` is
a sharp convex edge: the centres circle it at the radius ``r``, and the
estimate scatters about that value; at a kink of the centres' path (a tip
leaving one face for another) a local fit overshoots it.  So the corrected
estimate reads ``1 + r kappa`` below :data:`SHARP` as an edge's (a surface
radius of ``SHARP r``), and which side a tip could have traced is judged
over the curves' whole length, not at the contact: each curve's bend
(:func:`bends`, a parabola in arc length through the contact, never
tighter than a circular arc it fits and averaging a kink over the curve).
Where a curve's bend is convex beyond ``-EDGE`` (``1 + r kappa <= -EDGE``,
a radius under ``r / (1 + EDGE)``), that side is not tried; a touch with
no side left is an :class:`~tactrec.errors.InputError` naming its file
(:meth:`tactrec.features.Touch.with_estimate`).  A mesh's search of a touch
whose curves share one tip (a) does not read the corrected estimate; the
reported contact and spread, a closed-form surface's search, the moved
points of a session mixing radii and the ``paper`` method do.

With ``r = 0`` nothing here runs: the touch and the models are used as they
are.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .estimation import LocalGeometry
from .linalg import lstsq
from .surfaces.offset import FOOT_STEPS, Offset, foot_distance, offset

__all__ = ["EDGE", "SHARP", "bends", "traceable", "corrected", "surface_normals", "surface_curves", "Offset", "offset", "foot_distance",
           "FOOT_STEPS"]

#: a bend of the centres this much tighter than the tip (in ``1 + r kappa``) is a sharp edge's, within
#: the estimate's error; beyond it, no surface gives the data
EDGE = 0.25
#: the ``1 + r kappa`` a sharp edge's bend is given (the surface's radius there, over ``r``)
SHARP = 0.05
#: highest degree of the polynomial in arc length that gives a curve's tangent at each point
TANGENT_DEGREE = 6


def bends(curves, geometry: LocalGeometry) -> np.ndarray:
    """Each curve's bend over its whole length ``(k,)``: the normal curvature of the parabola
    ``h = a s + kappa s^2 / 2`` fitted (least squares) to the heights ``h`` of its points over the
    tangent plane at ``geometry``'s contact (along its normal) against their arc length ``s`` from
    the contact (convex negative).  A circular arc's is never tighter than the arc, and a kink (a
    tip's centres rounding an edge, where a local fit overshoots) is averaged over the curve."""
    out = []
    for curve in curves:
        x = np.asarray(curve, dtype=np.float64)
        step = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])
        s = step - step[int(np.argmin(np.linalg.norm(x - geometry.contact, axis=1)))]
        h = np.sum((x - geometry.contact) * geometry.normal, axis=1)                 # element-wise: no BLAS
        q = 0.5 * s * s                                                                # normal equations, no BLAS
        ss, sq, qq, sh, qh = (float(np.sum(a * b)) for a, b in ((s, s), (s, q), (q, q), (s, h), (q, h)))
        det = ss * qq - sq * sq
        out.append((ss * qh - sq * sh) / det if det > 0 else 0.0)
    return np.array(out, dtype=np.float64)


def traceable(curves, geometry: LocalGeometry, r: float) -> bool:
    """Whether a tip of radius ``r`` could trace ``curves`` with ``geometry.normal`` outward: no
    curve's bend (:func:`bends`) is convex more tightly than ``r / (1 + EDGE)`` (module text)."""
    return bool(1.0 + r * float(np.min(bends(curves, geometry))) > -EDGE)


def corrected(geometry: LocalGeometry, r: float) -> LocalGeometry:
    """The surface's estimate at the contact from the offset data's ``geometry`` (normal as the side
    to try: the outward one): contact moved by ``-r N``, ``kappa -> kappa / (1 + r kappa)`` for the
    principal curvatures (and, by Euler's theorem, the normal curvatures along the tangents);
    directions, tangents and normal kept.  ``1 + r kappa`` below :data:`SHARP` is a sharp edge's
    (taken as :data:`SHARP`, the curvature at least ``-1 / r``: module text)."""
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
    coef, _ = lstsq(V, curve)                                              # (degree + 1, 3)
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
