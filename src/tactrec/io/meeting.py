"""Where the curves meet: the contact point ``p`` of a touch (paper Section 3.1).

Used when a touch is read (:func:`check_meeting`: the curves must pass through
one point) and by the estimate at the contact (:func:`find_contact`, when the
data give no ``contact``).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["closest_on_polyline", "find_contact", "check_meeting"]


def closest_on_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Closest points ``(m, 3)`` on the polyline ``line`` ``(n, 3)`` to ``points``."""
    a, b = line[:-1], line[1:]
    ab = b - a
    denom = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    t = np.clip(np.einsum("msk,sk->ms", points[:, None, :] - a[None], ab) / denom, 0.0, 1.0)
    cand = a[None] + t[..., None] * ab[None]
    d2 = np.sum((cand - points[:, None, :]) ** 2, axis=2)
    return cand[np.arange(len(points)), np.argmin(d2, axis=1)]


def find_contact(curves) -> np.ndarray:
    """The point where the curves meet: least squares distance to all polylines.

    Starts at the data point closest to all other curves and alternates
    projections onto the curves (averaging them) until it settles.
    """
    curves = [np.asarray(c, dtype=np.float64) for c in curves]
    best, best_cost = None, np.inf
    for i, c in enumerate(curves):
        cost = np.zeros(len(c))
        for j, other in enumerate(curves):
            if j != i:
                cost += np.sum((closest_on_polyline(c, other) - c) ** 2, axis=1)
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best, best_cost = c[k], cost[k]
    x = best.copy()
    for _ in range(50):
        proj = np.array([closest_on_polyline(x[None], c)[0] for c in curves])
        new = proj.mean(axis=0)
        if np.linalg.norm(new - x) < 1e-12 * (1.0 + np.linalg.norm(x)):
            x = new
            break
        x = new
    return x


def check_meeting(data) -> np.ndarray:
    """Check that the curves pass through one point; return that point.

    Each curve must come within 2.5 point spacings of the contact (given, or
    found by :func:`find_contact`), and the curves' tangents there must span a
    plane.  Raises :class:`InputError` naming ``data.source``.
    """
    contact = data.contact if data.contact is not None else find_contact(data.curves)
    tol = 2.5 * data.spacing
    for i, c in enumerate(data.curves):
        d = float(np.linalg.norm(closest_on_polyline(contact[None], c)[0] - contact))
        if d > tol:
            where = "the given contact" if data.contact is not None else "a common point"
            raise InputError(f"the curves do not meet: curve {i + 1} passes {d:.4g} from {where} "
                             f"(more than 2.5 point spacings, {tol:.4g})", data.source)
    return contact
