"""Where the curves meet: the contact point ``p`` of a touch (paper Section 3.1).

Used when a touch is read (:func:`check_meeting`: the curves must pass through
one point) and by the estimate at the contact (:func:`find_contact`, when the
data give no ``contact``).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..linalg import norm3

__all__ = ["closest_on_polyline", "find_contact", "meeting_points", "meeting", "check_meeting", "MEETING"]


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
    for c, cost in zip(curves, _costs(curves)):
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best, best_cost = c[k], cost[k]
    return _settled(best.copy(), curves)


def _costs(curves) -> list[np.ndarray]:
    """Per curve, each point's summed squared distance to the other curves ``(n_i,)``."""
    out = []
    for i, c in enumerate(curves):
        cost = np.zeros(len(c))
        for j, other in enumerate(curves):
            if j != i:
                cost += np.sum((closest_on_polyline(c, other) - c) ** 2, axis=1)
        out.append(cost)
    return out


def _settled(x: np.ndarray, curves) -> np.ndarray:
    """From ``x (3,)``, projections onto the curves averaged until the point settles."""
    for _ in range(50):
        proj = np.array([closest_on_polyline(x[None], c)[0] for c in curves])
        new = proj.mean(axis=0)
        if norm3(new - x) < 1e-12 * (1.0 + norm3(x)):
            x = new
            break
        x = new
    return x


def meeting_points(curves, tolerance: float) -> list[np.ndarray]:
    """Every point ``(3,)`` the curves meet at, each curve passing within ``tolerance`` of it: from each
    local minimum, along a curve, of its points' summed squared distances to the other curves, the
    point settled as :func:`find_contact` settles its start; one per ``2 tolerance``, :func:`find_contact`'s
    first, then by the largest distance of a curve from them.

    Curves that pass near each other meet where they were traced, and also wherever their planes'
    common lines pierce the surface again within their length (the far face of a thin plate, a few
    millimetres off): where the traces miss each other by a little, such a far meeting can be the
    closer one."""
    curves = [np.asarray(c, dtype=np.float64) for c in curves]
    found = [find_contact(curves)]
    others = []
    limit = (len(curves) - 1) * tolerance ** 2
    for c, cost in zip(curves, _costs(curves)):
        low = np.r_[True, cost[1:] <= cost[:-1]] & np.r_[cost[:-1] <= cost[1:], True] & (cost <= limit)
        for k in np.flatnonzero(low):
            seen = found + [x for _, _, x in others]
            if any(np.linalg.norm(c[k] - y) <= 2 * tolerance for y in seen):
                continue
            x = _settled(c[k].copy(), curves)
            gaps = [float(np.linalg.norm(closest_on_polyline(x[None], cc)[0] - x)) for cc in curves]
            if max(gaps) <= tolerance and all(np.linalg.norm(x - y) > 2 * tolerance for y in seen):
                others.append((max(gaps), len(others), x))
    return found + [x for _, _, x in sorted(others, key=lambda o: o[:2])]


#: curves must pass this many median point spacings from their meeting point (:func:`check_meeting`)
MEETING = 2.5


def meeting(data) -> tuple[np.ndarray, np.ndarray]:
    """Where the curves of ``data`` meet and how far each passes from it: the point ``(3,)`` (the given
    ``contact``, else the least-squares point of :func:`find_contact`) and each curve's distance from
    it ``(k,)`` (data units)."""
    contact = np.asarray(data.contact, dtype=np.float64) if data.contact is not None else find_contact(data.curves)
    gaps = np.array([float(norm3(closest_on_polyline(contact[None], np.asarray(c, dtype=np.float64))[0] - contact))
                     for c in data.curves])
    return contact, gaps


def check_meeting(data) -> np.ndarray:
    """Check that the curves pass through one point; return that point.

    Curves that pass near each other rather than through one point are handled (the point is their
    least-squares meeting point, :func:`meeting`), but each curve must come within :data:`MEETING`
    median point spacings of it, and the curves' tangents there must span a plane.  Raises
    :class:`InputError` naming ``data.source``.
    """
    contact, gaps = meeting(data)
    tol = MEETING * data.spacing
    for i, d in enumerate(gaps):
        if d > tol:
            where = "the given contact" if data.contact is not None else "a common point"
            raise InputError(f"the curves do not meet: curve {i + 1} passes {d:.4g} from {where} "
                             f"(more than {MEETING} point spacings, {tol:.4g})", data.source)
    return contact
