"""Local geometry of a patch: a weighted fit of its surface (the patch's Section 3.1).

A patch samples the surface around the contact densely, so its normal and
principal curvatures come from one fit of all its points rather than from
curves: in the frame of the tangent plane at the contact, the height
``h(u, v)`` is fitted by a cubic polynomial (the cubic terms free the slope and
the curvature of the surface's own third-order bend, as ``degree=3`` does for
a curve), each point weighted by a Gaussian of its distance from the contact,
and refitted in the frame of the fitted normal.  The Gaussian's width is the
widest of :data:`WIDTHS` of the patch's reach whose slope and curvature agree,
within their standard errors under the patch's own noise, with every narrower
width's (as a curve's window is chosen): wide where the surface is smooth
enough to average the noise, narrow where its curvature changes across the
patch.  At the contact the gradient is then zero to first order and the
principal curvatures are the eigenvalues of the Hessian (sign convention of
:mod:`tactrec.surfaces.base`: negative on a convex surface).  The contact stays
the patch's middle point, a point the sensor recorded.

The patch's noise (:func:`patch_noise`) is measured on the data themselves:
each point's residual from a quadric fitted to its nearest neighbours, the
median absolute residual scaled to a Gaussian sigma.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .errors import InputError
from .estimation import LocalGeometry
from .linalg import dot3, eigh, gram, inverse_spd, lstsq, norm3, solve_spd

__all__ = ["estimate_patch", "patch_noise", "WIDTHS"]

#: the fit's Gaussian weights' sigmas tried, as shares of the patch's reach from the contact
WIDTHS = (0.2, 0.3, 0.45, 0.6)
#: and at least this many of the patch's spacings
NARROWEST = 3.0
#: half-width of the intervals the widths' estimates must share, in standard errors (as a curve's)
GAMMA = 3.5
#: neighbours of each point in its local quadric (:func:`patch_noise`), and the most points measured
NEIGHBOURS, NOISE_POINTS = 16, 4000


def _terms(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The cubic's design matrix: 1, u, v, u^2, u v, v^2, u^3, u^2 v, u v^2, v^3."""
    return np.stack([np.ones_like(u), u, v, u * u, u * v, v * v, u ** 3, u * u * v, u * v * v, v ** 3], axis=1)


def _fit(points: np.ndarray, contact: np.ndarray, normal: np.ndarray, first: np.ndarray, width: float,
         sigma: float = 0.0):
    """The weighted cubic of ``points`` over the plane through ``contact`` normal to ``normal``: its
    frame ``(e1, e2, n)``, coefficients, and the standard errors of the slope and second derivatives
    ``(c1, c2, 2 c3, c4, 2 c5)`` under noise ``sigma`` (the weighted fit's sandwich covariance).  In
    plain arithmetic (:mod:`tactrec.linalg`): the same digits under every BLAS kernel."""
    e1 = first - dot3(first, normal) * normal
    e1 = e1 / norm3(e1)
    e2 = np.cross(normal, e1)
    rel = points - contact
    u, v, h = dot3(rel, e1), dot3(rel, e2), dot3(rel, normal)
    w = np.sqrt(np.exp(-0.5 * (u * u + v * v) / (width * width)))
    A = _terms(u / width, v / width) * w[:, None]
    coef, _ = lstsq(A, h * w)
    powers = np.array([0, 1, 1, 2, 2, 2, 3, 3, 3, 3])
    coef = coef / width ** powers
    bread = inverse_spd(gram(A[None])[0])
    meat = gram((A * w[:, None])[None])[0]
    half = np.sum(bread[:, :, None] * meat[None, :, :], axis=1)              # bread @ meat, element-wise
    variance = np.sum(half * bread.T, axis=1) * sigma * sigma / width ** (2 * powers)
    se = np.sqrt(np.maximum(variance[[1, 2, 3, 4, 5]], 0.0)) * np.array([1, 1, 2, 1, 2])
    return (e1, e2, normal), coef, se


def _derivatives(c: np.ndarray) -> np.ndarray:
    """The slope and second derivatives ``(c1, c2, 2 c3, c4, 2 c5)`` of a fit's coefficients."""
    return np.array([c[1], c[2], 2 * c[3], c[4], 2 * c[5]])


def _width(points, contact, normal, first, reach: float, spacing: float, sigma: float) -> float:
    """The widest of :data:`WIDTHS` (times ``reach``, at least :data:`NARROWEST` spacings) whose slope
    and second derivatives agree with those of every narrower one: within the intersection of their
    intervals of :data:`GAMMA` standard errors under the patch's noise (as a curve's window is
    chosen, :func:`tactrec.estimation.fit_curve`)."""
    widths = sorted({max(f * reach, NARROWEST * spacing) for f in WIDTHS})
    lo, hi = np.full(5, -np.inf), np.full(5, np.inf)
    best = widths[0]
    for width in widths:
        _, c, se = _fit(points, contact, normal, first, width, sigma)
        value = _derivatives(c)
        lo, hi = np.maximum(lo, value - GAMMA * se), np.minimum(hi, value + GAMMA * se)
        if np.any(lo > hi):
            break
        best = width
    return best


def estimate_patch(data, noise: float) -> LocalGeometry:
    """Normal and principal curvatures at the contact of a patch touch ``data`` (its middle,
    :func:`tactrec.io.patch.spokes`), by the module's fit of all its points, its width chosen under
    the patch's ``noise`` (:func:`patch_noise`).  ``N`` points along
    ``data.outward`` where known, else so that the patch bends away from it (a convex guess; callers
    try :meth:`~tactrec.estimation.LocalGeometry.flipped` too)."""
    patch = data.patch
    points = patch.points
    contact = np.asarray(data.contact, dtype=np.float64)
    reach = float(np.max(np.linalg.norm(points - contact, axis=1)))
    normal = patch.frame[2]
    first = patch.frame[0]
    width = WIDTHS[-1] * reach
    for step in range(4):                                      # refit in the fitted normal's frame
        if step == 1:                                          # once the frame is near: the fit's width
            width = _width(points, contact, normal, first, reach, patch.spacing, noise)
        (e1, e2, n), c, _ = _fit(points, contact, normal, first, width)
        grad = np.array([c[1], c[2]])
        tilted = n - grad[0] * e1 - grad[1] * e2
        normal = tilted / norm3(tilted)
        contact = contact + c[0] * n
    (e1, e2, n), c, _ = _fit(points, contact, normal, first, width)
    if not np.all(np.isfinite(c)):
        raise InputError("the patch's points do not fix a surface (all on a line)", data.source)
    hessian = np.array([[2 * c[3], c[4]], [c[4], 2 * c[5]]])
    oriented = data.outward is not None
    sign = 1.0
    if oriented:
        sign = 1.0 if dot3(n, data.outward) >= 0 else -1.0
    elif np.trace(hessian) > 0:          # the patch bends towards n: the convex guess turns n over
        sign = -1.0
    n, hessian = sign * n, sign * hessian
    e2 = np.cross(n, e1)
    hessian = hessian if sign > 0 else hessian * np.array([[1.0, -1.0], [-1.0, 1.0]])   # v turned with e2
    k, vec = eigh(hessian)                                     # ascending: k2, k1
    d1 = vec[0, 1] * e1 + vec[1, 1] * e2
    d2 = np.cross(n, d1)
    tangents = np.array([_tangent(curve, contact, n) for curve in data.curves])
    kn = np.array([_normal_curvature(hessian, t, e1, e2) for t in tangents])
    middle = np.asarray(data.contact, dtype=np.float64)      # a recorded point, as a curves' meeting point is
    return LocalGeometry(middle, n, float(k[1]), float(k[0]), np.stack([d1, d2]), tangents, kn, oriented)


def _tangent(curve: np.ndarray, contact: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """A spoke's direction in the tangent plane at the contact."""
    d = np.asarray(curve[-1], dtype=np.float64) - np.asarray(curve[0], dtype=np.float64)
    d = d - dot3(d, normal) * normal
    return d / norm3(d)


def _normal_curvature(hessian: np.ndarray, t: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> float:
    x, y = float(dot3(t, e1)), float(dot3(t, e2))
    return float(hessian[0, 0] * x * x + 2.0 * hessian[0, 1] * x * y + hessian[1, 1] * y * y)


def patch_noise(patch) -> float:
    """The noise sigma of a patch's points along its normal: each point's residual from the quadric
    of its :data:`NEIGHBOURS` nearest (itself among them), over the root of one minus its leverage
    (its own weight in that fit), the median absolute one scaled to a Gaussian sigma.  On at most
    :data:`NOISE_POINTS` points, evenly taken; in plain arithmetic (:mod:`tactrec.linalg`)."""
    uvh = patch.plane_coordinates()
    k = min(NEIGHBOURS, len(uvh))
    chosen = np.arange(0, len(uvh), max(1, len(uvh) // NOISE_POINTS))
    _, near = cKDTree(uvh[:, :2]).query(uvh[chosen, :2], k=k)
    rel = uvh[near] - uvh[near[:, :1]]                        # (m, k, 3): about each chosen point
    u, v, h = rel[..., 0], rel[..., 1], rel[..., 2]
    span = np.maximum(np.max(np.hypot(u, v), axis=1), 1e-300)[:, None]
    u, v = u / span, v / span
    A = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=-1)           # (m, k, 6)
    G, b = gram(A, h)
    coef = solve_spd(G, b)
    own = A[:, 0]                                                                  # the point's row: (1, 0, ...)
    leverage = np.sum(own * solve_spd(G, own), axis=1)
    residual = h[:, 0] - np.sum(own * coef, axis=1)
    fair = leverage < 0.9                                     # a point its fit all but passes through tells nothing
    if not fair.any():
        return 0.0
    return float(np.median(np.abs(residual[fair]) / np.sqrt(1.0 - leverage[fair])) / 0.6745)
