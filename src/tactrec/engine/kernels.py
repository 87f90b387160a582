"""Compiled kernels of the hypothesis engine (numba; cached, no fastmath): the screen and the steps
on a mesh's distance field.

Every kernel is deterministic on every CPU: the parallel loops run over
hypotheses (``prange``), and each hypothesis sums its points in a fixed
order, in double precision, with no fused or reordered arithmetic.  The field
is read by :mod:`tactrec.surfaces.field_kernels`; a step on it is the one
point-to-plane step of :mod:`tactrec.registration.step`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..compiled import fork_safe
from ..registration.step import _add_plane, _damped_solve, _turn
from ..surfaces.field_kernels import BRICK, _sample, _sample_gradient

__all__ = ["screen_rotations", "field_best", "field_refine", "place_pairs", "triangle_screen", "triangle_poses", "warm"]

fork_safe()


@njit(cache=True)
def screen_rotations(local, count):
    """The data points ``local (m, 3)`` (in their contact frame: contact at the origin, normal along z)
    turned about z by ``count`` equal steps: ``(count, m, 3)``."""
    out = np.empty((count, local.shape[0], 3))
    for j in range(count):
        a = 2.0 * np.pi * j / count
        c = np.cos(a)
        s = np.sin(a)
        for k in range(local.shape[0]):
            out[j, k, 0] = c * local[k, 0] - s * local[k, 1]
            out[j, k, 1] = s * local[k, 0] + c * local[k, 1]
            out[j, k, 2] = local[k, 2]
    return out


@njit(cache=True, parallel=True)
def field_best(index, bricks, origin, inv_h, quantum, truncation, shift, frames, places, turned):
    """The screen: at each place, the rotation whose data lie nearest the surface.

    ``frames (n, 3, 3)`` (columns: two tangents and the outward normal of each place),
    ``places (n, 3)``, ``turned (r, m, 3)`` (:func:`screen_rotations`): hypothesis ``(i, j)``
    moves a data point ``x`` to ``frames[i] @ turned[j] + places[i]``.  Returns each place's
    least mean truncated distance ``(n,) float32`` and its rotation ``(n,) int64`` (the first of
    equal sums; a sum stops once past the best: its terms are non-negative)."""
    n = frames.shape[0]
    r = turned.shape[0]
    m = turned.shape[1]
    out = np.empty(n, dtype=np.float32)
    which = np.zeros(n, dtype=np.int64)
    for i in prange(n):
        F = frames[i]
        px = places[i, 0]
        py = places[i, 1]
        pz = places[i, 2]
        best = np.inf
        arg = 0
        for j in range(r):
            total = 0.0
            for k in range(m):
                a = turned[j, k, 0]
                b = turned[j, k, 1]
                c = turned[j, k, 2]
                x = F[0, 0] * a + F[0, 1] * b + F[0, 2] * c + px
                y = F[1, 0] * a + F[1, 1] * b + F[1, 2] * c + py
                z = F[2, 0] * a + F[2, 1] * b + F[2, 2] * c + pz
                total += abs(_sample(index, bricks, origin, inv_h, quantum, truncation, shift, x, y, z))
                if total > best:
                    break
            if total < best:
                best = total
                arg = j
        out[i] = best / m
        which[i] = arg
    return out, which


@njit(cache=True, parallel=True)
def field_refine(index, bricks, origin, inv_h, quantum, truncation, shift, R, t, x, iterations):
    """Point-to-plane Gauss-Newton (damped) on the field: poses ``R (h, 3, 3), t (h, 3)`` of data
    ``x (m, 3)`` take ``iterations`` steps, each linearising the signed distances about the pose
    (planes normal to the field's gradient).  Points beyond the truncation take no part in a step.
    Returns the poses and their mean truncated distances ``(h,)`` after the last step."""
    h = R.shape[0]
    m = x.shape[0]
    Ro = R.copy()
    to = t.copy()
    score = np.empty(h)
    for i in prange(h):
        Ri = Ro[i]
        ti = to[i]
        g = np.empty(3)
        A = np.empty((6, 6))
        b = np.empty(6)
        step = np.empty(6)
        dR = np.empty((3, 3))
        tmp = np.empty((3, 3))
        J = np.empty(6)
        for _ in range(iterations):
            for p in range(6):
                b[p] = 0.0
                for q in range(6):
                    A[p, q] = 0.0
            for k in range(m):
                y0 = Ri[0, 0] * x[k, 0] + Ri[0, 1] * x[k, 1] + Ri[0, 2] * x[k, 2] + ti[0]
                y1 = Ri[1, 0] * x[k, 0] + Ri[1, 1] * x[k, 1] + Ri[1, 2] * x[k, 2] + ti[1]
                y2 = Ri[2, 0] * x[k, 0] + Ri[2, 1] * x[k, 1] + Ri[2, 2] * x[k, 2] + ti[2]
                d = _sample_gradient(index, bricks, origin, inv_h, quantum, truncation, shift, y0, y1, y2, g)
                if abs(d) < truncation:
                    _add_plane(y0, y1, y2, g[0], g[1], g[2], d, J, A, b)
            if not _damped_solve(A, b, step):
                break
            _turn(step, dR, tmp, Ri, ti, Ri, ti)
        score[i] = _posed_sum(index, bricks, origin, inv_h, quantum, truncation, shift, Ri, ti, x, np.inf) / m
    return Ro, to, score


@njit(cache=True, nogil=True)
def _posed_sum(index, bricks, origin, inv_h, quantum, truncation, shift, R, t, x, cap):
    """The sum of the truncated distances of the points ``x (m, 3)`` moved by ``R, t``, in their order;
    it stops once past ``cap`` (its terms are non-negative: the full sum is past it too)."""
    total = 0.0
    for k in range(x.shape[0]):
        y0 = R[0, 0] * x[k, 0] + R[0, 1] * x[k, 1] + R[0, 2] * x[k, 2] + t[0]
        y1 = R[1, 0] * x[k, 0] + R[1, 1] * x[k, 1] + R[1, 2] * x[k, 2] + t[1]
        y2 = R[2, 0] * x[k, 0] + R[2, 1] * x[k, 1] + R[2, 2] * x[k, 2] + t[2]
        total += abs(_sample(index, bricks, origin, inv_h, quantum, truncation, shift, y0, y1, y2))
        if total > cap:
            break
    return total


@njit(cache=True, nogil=True)
def _degrees_between(ax, ay, az, bx, by, bz):
    """The angle between unit vectors ``a`` and ``b``, degrees."""
    return np.degrees(np.arccos(min(max(ax * bx + ay * by + az * bz, -1.0), 1.0)))


@njit(cache=True, nogil=True)
def _pair_matches(P, N, v, w, length, tol, ends):
    """Whether the places ``v, w`` lie ``length`` apart (within ``tol``) and their normals make the
    angles ``ends`` gives: ``(angle of a's normal to the chord, allowance, angle of b's, allowance,
    angle between the two normals, allowance)``, an allowance below zero testing nothing."""
    dx = P[w, 0] - P[v, 0]
    dy = P[w, 1] - P[v, 1]
    dz = P[w, 2] - P[v, 2]
    d = np.sqrt(dx * dx + dy * dy + dz * dz)
    if not (abs(d - length) <= tol and d > 0.0):
        return False
    ux, uy, uz = dx / d, dy / d, dz / d
    if ends[1] >= 0.0 and not abs(_degrees_between(N[v, 0], N[v, 1], N[v, 2], ux, uy, uz) - ends[0]) <= ends[1]:
        return False
    if ends[3] >= 0.0 and not abs(_degrees_between(N[w, 0], N[w, 1], N[w, 2], ux, uy, uz) - ends[2]) <= ends[3]:
        return False
    if ends[5] >= 0.0 and not abs(_degrees_between(N[v, 0], N[v, 1], N[v, 2], N[w, 0], N[w, 1], N[w, 2])
                                  - ends[4]) <= ends[5]:
        return False
    return True


@njit(cache=True, parallel=True)
def place_pairs(P, N, length, tol, ends):
    """The ordered pairs of distinct places ``(v, w)`` of ``P (p, 3)`` (outward normals ``N``) as far
    apart as ``length`` within ``tol``, whose normals make the angles of ``ends`` (:func:`_pair_matches`):
    ``v (q,), w (q,)`` in the order of ``v``, then ``w``."""
    p = P.shape[0]
    count = np.zeros(p, dtype=np.int64)
    for v in prange(p):
        c = 0
        for w in range(p):
            if _pair_matches(P, N, v, w, length, tol, ends):
                c += 1
        count[v] = c
    start = np.zeros(p + 1, dtype=np.int64)
    for v in range(p):
        start[v + 1] = start[v] + count[v]
    out_v = np.empty(start[p], dtype=np.int64)
    out_w = np.empty(start[p], dtype=np.int64)
    for v in prange(p):
        k = start[v]
        for w in range(p):
            if _pair_matches(P, N, v, w, length, tol, ends):
                out_v[k] = v
                out_w[k] = w
                k += 1
    return out_v, out_w


@njit(cache=True, nogil=True, error_model="numpy")
def _triangle_pose(P, va, wb, wc, data_frame, xa, R, t):
    """Into ``R (3, 3), t (3,)``: the pose moving the data triangle whose frame is ``data_frame``
    (columns: along ``ab``, in the plane towards ``c``, the plane's normal) and whose first corner is
    ``xa (3,)`` onto the places ``P[va], P[wb], P[wc]``, frame onto frame.  In scalars (no array a
    pose); a division by zero gives inf or NaN, as numpy's arithmetic does."""
    ax, ay, az = P[wb, 0] - P[va, 0], P[wb, 1] - P[va, 1], P[wb, 2] - P[va, 2]
    n = np.sqrt(ax * ax + ay * ay + az * az)
    ax, ay, az = ax / n, ay / n, az / n
    fx, fy, fz = P[wc, 0] - P[va, 0], P[wc, 1] - P[va, 1], P[wc, 2] - P[va, 2]
    cx, cy, cz = ay * fz - az * fy, az * fx - ax * fz, ax * fy - ay * fx
    n = max(np.sqrt(cx * cx + cy * cy + cz * cz), 1e-300)
    cx, cy, cz = cx / n, cy / n, cz / n
    bx, by, bz = cy * az - cz * ay, cz * ax - cx * az, cx * ay - cy * ax
    for k in range(3):
        R[0, k] = ax * data_frame[k, 0] + bx * data_frame[k, 1] + cx * data_frame[k, 2]
        R[1, k] = ay * data_frame[k, 0] + by * data_frame[k, 1] + cy * data_frame[k, 2]
        R[2, k] = az * data_frame[k, 0] + bz * data_frame[k, 1] + cz * data_frame[k, 2]
    for i in range(3):
        t[i] = P[va, i] - (R[i, 0] * xa[0] + R[i, 1] * xa[1] + R[i, 2] * xa[2])


@njit(cache=True, parallel=True)
def triangle_screen(index, bricks, origin, inv_h, quantum, truncation, shift, P, v1, w1, w2, first, count, offset,
                    bc, tol, data_frame, xa, x, bound):
    """The screen of contacts: each triangle of places ``(v1[r], w1[r], w2[first[r] + j])``, ``j <
    count[r]`` (pairs of ``ab`` joined to the pairs of ``ac`` that share ``a``'s place), posed by
    :func:`_triangle_pose` and scored by the mean truncated distance of the points ``x (m, 3)`` on the
    field.  Returns ``(sum(count),) float32`` at ``offset[r] + j``: NaN where the third side is not
    ``bc`` within ``tol`` (no pose), inf where the sum passes ``bound`` times ``m`` (its terms are
    non-negative, so such a pose's mean is past ``bound``)."""
    rows = v1.shape[0]
    m = x.shape[0]
    out = np.empty(offset[rows - 1] + count[rows - 1] if rows else 0, dtype=np.float32)
    cap = bound * m
    for r in prange(rows):
        R = np.empty((3, 3))
        t = np.empty(3)
        for j in range(count[r]):
            wc = w2[first[r] + j]
            dx = P[wc, 0] - P[w1[r], 0]
            dy = P[wc, 1] - P[w1[r], 1]
            dz = P[wc, 2] - P[w1[r], 2]
            if abs(np.sqrt(dx * dx + dy * dy + dz * dz) - bc) > tol:
                out[offset[r] + j] = np.nan
                continue
            _triangle_pose(P, v1[r], w1[r], wc, data_frame, xa, R, t)
            total = _posed_sum(index, bricks, origin, inv_h, quantum, truncation, shift, R, t, x, cap)
            out[offset[r] + j] = np.inf if total > cap else total / m
    return out


@njit(cache=True)
def triangle_poses(P, va, wb, wc, data_frame, xa):
    """The poses :func:`triangle_screen` scored, of the triangles of places ``(va, wb, wc)`` each
    ``(h,)``: ``R (h, 3, 3), t (h, 3)``, the same bits."""
    h = va.shape[0]
    R = np.empty((h, 3, 3))
    t = np.empty((h, 3))
    for i in range(h):
        _triangle_pose(P, va[i], wb[i], wc[i], data_frame, xa, R[i], t[i])
    return R, t


def warm() -> None:
    """Load every kernel's compiled code (from numba's cache, or compiling it) by calling each once on
    a tiny empty field, with the argument types and layouts a search passes."""
    from ..index.kernels import ring_distances
    from ..registration.anderson import anderson
    from ..registration.step import covariance, jacobian, normal_matrix, plane_step, prior_steps
    from ..surfaces.field_kernels import field_gradient, field_lookup

    field = (np.full((1, 1, 1), -1, dtype=np.int32), np.zeros((1, BRICK + 1, BRICK + 1, BRICK + 1), dtype=np.int16),
             np.zeros(3), 1.0, 1.0, 1.0, 0.0)
    points = np.zeros((2, 3))
    eye = np.ascontiguousarray(np.broadcast_to(np.eye(3), (2, 3, 3)))
    field_lookup(*field, points)
    field_gradient(*field, points)
    turned = screen_rotations(points, 2)
    field_best(*field, eye, points, turned)
    field_refine(*field, eye, points, points, 1)
    one = np.zeros(1, dtype=np.int64)
    place_pairs(points, eye[0], 1.0, 1.0, np.full(6, -1.0))
    triangle_screen(*field, points, one, one, one, one, one, one, 1.0, 1.0, np.eye(3), points[0], points, np.inf)
    triangle_poses(points, one, one, one, np.eye(3), points[0])
    plane_step(eye, points, np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), np.zeros((2, 2)))
    jacobian(points, points)
    normal_matrix(points, points)
    covariance(points, points)
    prior_steps(np.eye(6), np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), np.zeros((2, 2)), np.ones((2, 2)))
    anderson(eye, points, eye, points, eye, points, np.zeros((2, 4, 6)), np.zeros((2, 4, 6)), np.zeros(2, dtype=np.int64),
             1.0)
    ring_distances(np.zeros((1, 2), dtype=np.float32), np.zeros(1, dtype=np.int64), np.zeros((1, 2)),
                   np.ones(1, dtype=np.int8), np.zeros(1), np.zeros(1, dtype=np.int8))
