"""Local geometry at the contact point from the data curves (paper Section 3.1).

* Section 3.1.1 -- per curve, a parabola ``y = a x^2 + b x + c`` in its sampling
  plane gives the tangent ``T_i``, principal normal ``N_i`` and curvature
  ``kappa_i`` at ``p``; the data normal ``N`` minimises ``sum (N . T_i)^2``
  (eq. 1).  By default a cubic term is fitted alongside (``degree=3``): in a
  window centred on ``p`` the quadratic coefficient, hence the curvature, is
  (nearly) the parabola's, while the tangent is no longer tilted by the
  curve's cubic term, which otherwise tilts the normal by up to 0.05 rad on
  the paper's surfaces; ``degree=2`` is the plain parabola.  The window is
  chosen per curve from its noise (see :func:`fit_curve`).
* Section 3.1.2 -- normal curvatures ``kn_i = kappa_i (N_i . N)`` (Meusnier) and,
  by Euler's theorem (eqs. 2-4), the principal curvatures: the paper's closed
  form for three curves (eqs. 5-6) or linear least squares
  ``kn_i = H + B cos 2 psi_i + C sin 2 psi_i`` for three or more.

Sign convention as in :mod:`tactrec.surfaces.base`: with ``N`` pointing out of
the object, a convex surface has negative curvatures; ``k1 >= k2``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .errors import InputError
from .io.meeting import find_contact
from .io.touch import TactileData
from .linalg import dot3, eigh, eigvalsh, gram, inverse_spd, lstsq, norm3

__all__ = [
    "CurveFit", "LocalGeometry", "fit_curve", "data_normal", "principal_curvatures",
    "find_contact", "estimate", "noise_level",
]


@dataclasses.dataclass(frozen=True)
class CurveFit:
    """Differential geometry of one data curve at ``p`` (Section 3.1.1).

    Attributes
    ----------
    tangent : (3,) unit tangent ``T_i``
    principal_normal : (3,) unit principal normal ``N_i`` (towards the centre of curvature)
    curvature : float, ``kappa_i >= 0``
    plane_normal : (3,) unit normal of the fitted sampling plane
    """

    tangent: np.ndarray
    principal_normal: np.ndarray
    curvature: float
    plane_normal: np.ndarray


@dataclasses.dataclass(frozen=True)
class LocalGeometry:
    """Estimated normal and principal curvatures at the contact point.

    Attributes
    ----------
    contact : (3,) the common point ``p`` of the curves, data frame
    normal : (3,) unit data normal ``N`` (eq. 1)
    k1, k2 : principal curvatures, ``k1 >= k2`` (eqs. 5-6 or least squares)
    directions : (2, 3) principal directions for ``k1`` and ``k2``; ``d1 x d2 = N``
    tangents : (k, 3) curve tangents ``T_i`` at ``p``
    normal_curvatures : (k,) ``kn_i = kappa_i (N_i . N)``
    oriented : True if ``N`` was oriented by an ``outward`` hint
    """

    contact: np.ndarray
    normal: np.ndarray
    k1: float
    k2: float
    directions: np.ndarray
    tangents: np.ndarray
    normal_curvatures: np.ndarray
    oriented: bool

    @property
    def curvatures(self) -> tuple[float, float]:
        return (self.k1, self.k2)

    @property
    def reported(self) -> list | None:
        """``[k1, k2]`` as a result gives them; None where the touch gives no curvature (contacts)."""
        return [self.k1, self.k2] if np.isfinite(self.k1) else None

    def flipped(self) -> "LocalGeometry":
        """The same estimate with the normal reversed: ``(k1, k2) -> (-k2, -k1)``."""
        return dataclasses.replace(
            self,
            normal=-self.normal,
            k1=-self.k2,
            k2=-self.k1,
            directions=self.directions[::-1].copy(),
            normal_curvatures=-self.normal_curvatures,
        )


# ---------------------------------------------------------------------- curves
def fit_curve(points: np.ndarray, contact: np.ndarray, *, window: int | str | None = "auto",
              degree: int = 3) -> CurveFit:
    """Fit ``y = a x^2 + b x + c`` (plus higher terms) in the curve's sampling plane around ``contact``.

    Parameters
    ----------
    points : (n, 3) float
        Ordered points of one curve.
    contact : (3,) float
        The point ``p`` at which to differentiate.
    window : int, ``"auto"`` or None
        Which points to fit: ``None``, all of them; an integer ``w``, the
        ``2 w + 1`` points nearest to ``p`` along the curve; ``"auto"``
        (default), the widest window whose estimates agree with those of every
        narrower one (intersection of confidence intervals, +/- 3.5 standard
        errors of the slope and the curvature, with the noise estimated from
        the curve's third differences), and no wider than ``0.3 / kappa`` (a
        parabola's relative curvature bias on a circle is about
        ``0.21 (h kappa)^2``).  A short window is biased by the curve's
        higher-order terms less, a long one averages noise better.
    degree : int
        Degree of the fitted polynomial: 2 is the paper's parabola; 3 (the
        default) frees the tangent of the cubic term's bias; 4 the curvature
        of the quartic term's, at the price of more sensitivity to noise.
    """
    points = np.asarray(points, dtype=np.float64)
    i0 = int(np.argmin(np.linalg.norm(points - contact, axis=1)))
    if window == "auto":
        return _fit_adaptive(points, contact, i0, degree)
    if window is not None:
        points = points[max(0, i0 - int(window)): i0 + int(window) + 1]
    return _fit_polynomial(points, contact, degree)[0]


GAMMA = 3.5        # half-width of the confidence intervals, in standard errors
FACETS = 4.0       # smallest window, in straight pieces of a polyline, each side of p
BIAS_LIMIT = 0.3   # windows no wider than this over kappa: a parabola's relative bias ~ 0.21 (h kappa)^2


def noise_level(points: np.ndarray) -> float:
    """Noise sigma per coordinate from third differences (robust: median absolute value)."""
    d3 = np.diff(points, n=3, axis=0)
    if len(d3) == 0:
        return 0.0
    # each coordinate of a third difference of white noise has variance 20 sigma^2
    return float(np.median(np.abs(d3)) / 0.6745 / np.sqrt(20.0))


def _facet_length(points: np.ndarray) -> float:
    """Points per straight piece of the curve: about 1 for a smooth or noisy
    curve, ``m`` for a polyline whose corners are ``m`` points apart (a plane
    section of a triangle mesh).  The participation ratio of the turning
    angles, ``(sum theta)^2 / sum theta^2``, counts the points that carry the
    turning."""
    chords = np.diff(points, axis=0)
    chords = chords / np.maximum(np.linalg.norm(chords, axis=1, keepdims=True), 1e-300)
    theta = np.arccos(np.clip(np.sum(chords[1:] * chords[:-1], axis=1), -1.0, 1.0))
    total = float(np.sum(theta))
    if total <= 0.0:
        return 1.0
    return max(1.0, len(theta) * float(np.sum(theta * theta)) / (total * total))


def _fit_adaptive(points: np.ndarray, contact: np.ndarray, i0: int, degree: int) -> CurveFit:
    sigma = noise_level(points)
    plane = _sampling_plane(points)          # the whole curve fixes its plane best
    n_side = max(i0, len(points) - 1 - i0)
    # a window must span a few straight pieces: below that, it sees the facets, not the surface
    smallest = min(n_side, max(4, int(np.ceil(FACETS * _facet_length(points)))))
    widths = sorted({w for w in np.unique(np.round(np.geomspace(smallest, max(n_side, smallest), 12)).astype(int))
                     if w >= smallest} | {n_side})
    best = None
    lo = np.array([-np.inf, -np.inf])
    hi = np.array([np.inf, np.inf])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    for w in widths:
        sub = points[max(0, i0 - w): i0 + w + 1]
        if len(sub) < degree + 2:
            continue
        if best is not None and w > 5 and min(arc[i0] - arc[max(0, i0 - w)], arc[min(len(arc) - 1, i0 + w)] - arc[i0]) \
                > BIAS_LIMIT / max(best.curvature, 1e-300):
            break
        fit, value, se = _fit_polynomial(sub, contact, degree, sigma=sigma, plane=plane)
        lo = np.maximum(lo, value - GAMMA * se)
        hi = np.minimum(hi, value + GAMMA * se)
        if best is not None and np.any(lo > hi):
            break
        best = fit
    return best if best is not None else _fit_polynomial(points, contact, degree, plane=plane)[0]


def _sampling_plane(points: np.ndarray):
    """In-plane axes ``e1`` (along the curve), ``e2`` and the plane's normal."""
    centred = points - points.mean(axis=0)
    _, v = eigh(gram(centred[None])[0])                  # the scatter's axes, largest last
    e1, plane_normal = v[:, 2], v[:, 0]
    if dot3(points[-1] - points[0], e1) < 0:             # e1 runs from the first point to the last
        e1 = -e1
    return e1, np.cross(plane_normal, e1), plane_normal


def _fit_polynomial(points: np.ndarray, contact: np.ndarray, degree: int, *, sigma: float = 0.0, plane=None):
    """Least-squares polynomial in the sampling plane (``plane``, or fitted to
    ``points``).  Returns the fit, the slope and second derivative ``(2,)`` at
    ``contact`` and their standard errors ``(2,)`` for noise ``sigma``."""
    e1, e2, plane_normal = _sampling_plane(points) if plane is None else plane
    rel = points - contact
    x, y = dot3(rel, e1), dot3(rel, e2)
    h = float(np.max(np.abs(x))) or 1.0
    X = x / h
    if degree < 2:
        raise ValueError("the fitted polynomial needs degree 2 or more")
    A = np.vander(X, degree + 1, increasing=True)              # 1, X, X^2, ...
    coef, rank = lstsq(A, y)
    if rank < degree + 1:
        raise ValueError(f"too few distinct points to fit a polynomial of degree {degree}")
    slope = coef[1] / h
    second = 2.0 * coef[2] / (h * h)
    norm = np.sqrt(1.0 + slope * slope)
    tangent = (e1 + slope * e2) / norm
    curvature = abs(second) / norm**3
    pn2 = np.sign(second) * np.array([-slope, 1.0]) / norm if second != 0 else np.array([-slope, 1.0]) / norm
    principal_normal = pn2[0] * e1 + pn2[1] * e2
    cov = inverse_spd(gram(A[None])[0])                  # full rank: A's columns are independent
    se = sigma * np.sqrt(np.array([cov[1, 1] / h**2, 4.0 * cov[2, 2] / h**4]))
    fit = CurveFit(tangent, principal_normal, float(curvature), plane_normal)
    return fit, np.array([slope, second]), se


def data_normal(tangents: np.ndarray) -> np.ndarray:
    """Unit ``N`` minimising ``sum_i (N . T_i)^2`` (eq. 1): the eigenvector of
    ``sum T_i T_i^T`` with the smallest eigenvalue."""
    T = np.asarray(tangents, dtype=np.float64)
    _, v = eigh(gram(T[None])[0])
    return v[:, 0]


# ---------------------------------------------------------------------- curvatures
def _tangent_angles(tangents: np.ndarray, normal: np.ndarray):
    b1 = tangents[0] - dot3(tangents[0], normal) * normal
    b1 /= norm3(b1)
    b2 = np.cross(normal, b1)
    psi = np.arctan2(dot3(tangents, b2), dot3(tangents, b1))
    return psi, b1, b2


def principal_curvatures(tangents: np.ndarray, normal: np.ndarray, kn: np.ndarray, *,
                         method: str = "auto") -> tuple[float, float, np.ndarray]:
    """Principal curvatures from normal curvatures along known tangents (Euler).

    Parameters
    ----------
    tangents : (k, 3) unit tangents ``T_i`` (k >= 3)
    normal : (3,) unit normal ``N``
    kn : (k,) normal curvatures along ``T_i``
    method : ``"closed-form"`` (paper eqs. 5-6, exactly three curves),
        ``"least-squares"`` (any k >= 3) or ``"auto"`` (closed form for three).

    Returns
    -------
    k1, k2 : float, ``k1 >= k2``
    directions : (2, 3) principal directions, ``d1 x d2 = N``
    """
    tangents = np.asarray(tangents, dtype=np.float64)
    kn = np.asarray(kn, dtype=np.float64)
    psi, b1, b2 = _tangent_angles(tangents, normal)
    if method == "auto":
        method = "closed-form" if len(kn) == 3 else "least-squares"
    result = None
    if method == "closed-form":
        if len(kn) != 3:
            raise ValueError("the closed form (eqs. 5-6) takes exactly three curves")
        result = _closed_form(psi, kn)
    elif method != "least-squares":
        raise ValueError(f"unknown method {method!r}")
    if result is None:
        A = np.stack([np.ones_like(psi), np.cos(2 * psi), np.sin(2 * psi)], axis=1)
        (H, B, C), _ = lstsq(A, kn)
        R = np.hypot(B, C)
        k1, k2, angle = H + R, H - R, 0.5 * np.arctan2(C, B)
    else:
        k1, k2, angle = result
    d1 = np.cos(angle) * b1 + np.sin(angle) * b2
    d2 = np.cross(normal, d1)
    return float(k1), float(k2), np.stack([d1, d2])


def _closed_form(psi: np.ndarray, kn: np.ndarray):
    """Eqs. (5)-(6): solve eqs. (2)-(4) for theta, k1, k2.

    ``theta_1, theta_2`` are the angles from ``T_alpha`` to ``T_beta``,
    ``T_gamma``; from (2)-(4),
    ``tan 2 theta = (B sin t1 - A sin t2) / (A cos t2 - B cos t1)`` with
    ``A = (ka - kb) sin t2``, ``B = (ka - kg) sin t1``; then eq. (6).
    Returns ``None`` where the system is degenerate.
    """
    ka, kb, kg = kn
    t1, t2 = psi[1] - psi[0], psi[2] - psi[0]
    A = (ka - kb) * np.sin(t2)
    B = (ka - kg) * np.sin(t1)
    theta = 0.5 * np.arctan2(B * np.sin(t1) - A * np.sin(t2), A * np.cos(t2) - B * np.cos(t1))
    den = np.cos(theta) ** 2 * np.sin(theta + t1) ** 2 - np.cos(theta + t1) ** 2 * np.sin(theta) ** 2
    if abs(den) < 1e-9:
        return None
    k1 = (ka * np.sin(theta + t1) ** 2 - kb * np.sin(theta) ** 2) / den
    k2 = (kb * np.cos(theta) ** 2 - ka * np.cos(theta + t1) ** 2) / den
    # theta is the angle from the k1 direction back to T_alpha: the k1 direction is at -theta
    angle = psi[0] - theta
    if k1 < k2:
        k1, k2, angle = k2, k1, angle + 0.5 * np.pi
    return k1, k2, angle


# ---------------------------------------------------------------------- all together
def estimate(data: TactileData, *, window: int | str | None = "auto", degree: int = 3,
             method: str = "auto") -> LocalGeometry:
    """Normal and principal curvatures at the contact point of ``data``.

    ``window`` and ``degree`` go to :func:`fit_curve`; ``method`` to
    :func:`principal_curvatures` (the paper's closed form for three curves).

    If ``data.outward`` is given, ``N`` points along it; otherwise ``N`` is
    chosen so that the curves bend away from it (a convex guess) and callers
    should also try :meth:`LocalGeometry.flipped`.

    A patch's curves are its spokes; a patch's own geometry, a fit of all its points, is
    :func:`tactrec.estimation_patch.estimate_patch`.
    """
    contact = data.contact if data.contact is not None else find_contact(data.curves)
    try:
        fits = [fit_curve(c, contact, window=window, degree=degree) for c in data.curves]
    except ValueError as exc:
        raise InputError(str(exc), data.source) from None
    tangents = np.array([f.tangent for f in fits])
    w = eigvalsh(gram(tangents[None])[0])
    if w[1] < 1e-3 * w[2]:                   # three planes about 2 degrees apart; the paper goes down to 10
        raise InputError("the curves are (nearly) tangent to one another at the contact: "
                         "their planes must cross at distinct angles", data.source)
    normal = data_normal(tangents)
    if data.outward is not None:
        oriented = True
        if dot3(normal, data.outward) < 0:
            normal = -normal
    else:
        oriented = False
        offsets = np.concatenate([dot3(c - contact, normal) for c in data.curves])
        if np.mean(offsets) > 0:
            normal = -normal
    kn = np.array([f.curvature * dot3(f.principal_normal, normal) for f in fits])
    k1, k2, directions = principal_curvatures(tangents, normal, kn, method=method)
    return LocalGeometry(contact, normal, k1, k2, directions, tangents, kn, oriented)
