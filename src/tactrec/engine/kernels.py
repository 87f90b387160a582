"""Compiled kernels of the hypothesis engine (numba; cached, no fastmath).

Every kernel is deterministic on every CPU: the parallel loops run over
hypotheses (``prange``), and each hypothesis sums its points in a fixed
order, in double precision, with no fused or reordered arithmetic.

The field is the sparse brick grid of :class:`tactrec.surfaces.mesh_field.DistanceField`:
``index (bx, by, bz) int32`` names the brick of each block of ``BRICK`` cells
(-1: none, every cell at least the truncation away), ``bricks (nb, BRICK + 1,
BRICK + 1, BRICK + 1) int16`` hold the signed distance at the cells' corners
in units of ``quantum``; a point outside every brick is ``truncation`` away.
A field's ``shift`` is subtracted from every sample: the field of the
surface offset outward by that much, read from the same bricks
(:meth:`tactrec.surfaces.mesh_field.DistanceField.shifted`).
"""

from __future__ import annotations

import numpy as np
from numba import config, njit, prange

from . import BRICK

if config.THREADING_LAYER == "default":
    # the built-in scheduler: always there, and safe in a process forked after a kernel ran (a
    # Recognizer's workers); GNU OpenMP, numba's other default, ends such a process
    config.THREADING_LAYER = "workqueue"

__all__ = ["field_lookup", "field_gradient", "screen_rotations", "field_best", "field_refine", "plane_step", "warm"]



@njit(cache=True, nogil=True)
def _cell(index, origin, inv_h, x, y, z):
    """The brick of the cell holding one point and the point's place in it: ``(b, lx, ly, lz, fx, fy,
    fz)``, ``b`` -1 outside every brick."""
    gx = (x - origin[0]) * inv_h
    gy = (y - origin[1]) * inv_h
    gz = (z - origin[2]) * inv_h
    if not (gx >= 0.0 and gy >= 0.0 and gz >= 0.0):          # also NaN
        return -1, 0, 0, 0, 0.0, 0.0, 0.0
    ix = int(gx)
    iy = int(gy)
    iz = int(gz)
    bx = ix // BRICK
    by = iy // BRICK
    bz = iz // BRICK
    if bx >= index.shape[0] or by >= index.shape[1] or bz >= index.shape[2]:
        return -1, 0, 0, 0, 0.0, 0.0, 0.0
    return index[bx, by, bz], ix - bx * BRICK, iy - by * BRICK, iz - bz * BRICK, gx - ix, gy - iy, gz - iz


@njit(cache=True, nogil=True)
def _sample(index, bricks, origin, inv_h, quantum, truncation, shift, x, y, z):
    """Signed distance at one point by trilinear interpolation, less ``shift``, within ``truncation``
    (``truncation`` outside every brick)."""
    b, lx, ly, lz, fx, fy, fz = _cell(index, origin, inv_h, x, y, z)
    if b < 0:
        return truncation
    c = bricks[b]
    c00 = c[lx, ly, lz] * (1.0 - fx) + c[lx + 1, ly, lz] * fx
    c10 = c[lx, ly + 1, lz] * (1.0 - fx) + c[lx + 1, ly + 1, lz] * fx
    c01 = c[lx, ly, lz + 1] * (1.0 - fx) + c[lx + 1, ly, lz + 1] * fx
    c11 = c[lx, ly + 1, lz + 1] * (1.0 - fx) + c[lx + 1, ly + 1, lz + 1] * fx
    c0 = c00 * (1.0 - fy) + c10 * fy
    c1 = c01 * (1.0 - fy) + c11 * fy
    return _within((c0 * (1.0 - fz) + c1 * fz) * quantum - shift, truncation)


@njit(cache=True, nogil=True)
def _within(d, truncation):
    """``d`` clipped to ``[-truncation, truncation]`` (a shifted field's band is narrower than its
    samples')."""
    if d > truncation:
        return truncation
    if d < -truncation:
        return -truncation
    return d


@njit(cache=True, nogil=True)
def _sample_gradient(index, bricks, origin, inv_h, quantum, truncation, shift, x, y, z, out):
    """Signed distance at one point less ``shift`` and its gradient (into ``out (3,)``; zero outside
    every brick, and where the distance is clipped to ``truncation``)."""
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    b, lx, ly, lz, fx, fy, fz = _cell(index, origin, inv_h, x, y, z)
    if b < 0:
        return truncation
    c = bricks[b]
    v000 = float(c[lx, ly, lz])
    v100 = float(c[lx + 1, ly, lz])
    v010 = float(c[lx, ly + 1, lz])
    v110 = float(c[lx + 1, ly + 1, lz])
    v001 = float(c[lx, ly, lz + 1])
    v101 = float(c[lx + 1, ly, lz + 1])
    v011 = float(c[lx, ly + 1, lz + 1])
    v111 = float(c[lx + 1, ly + 1, lz + 1])
    c00 = v000 * (1.0 - fx) + v100 * fx
    c10 = v010 * (1.0 - fx) + v110 * fx
    c01 = v001 * (1.0 - fx) + v101 * fx
    c11 = v011 * (1.0 - fx) + v111 * fx
    c0 = c00 * (1.0 - fy) + c10 * fy
    c1 = c01 * (1.0 - fy) + c11 * fy
    s = quantum * inv_h
    out[0] = (((v100 - v000) * (1.0 - fy) + (v110 - v010) * fy) * (1.0 - fz)
              + ((v101 - v001) * (1.0 - fy) + (v111 - v011) * fy) * fz) * s
    out[1] = (c10 - c00) * (1.0 - fz) * s + (c11 - c01) * fz * s
    out[2] = (c1 - c0) * s
    d = (c0 * (1.0 - fz) + c1 * fz) * quantum - shift
    if abs(d) >= truncation:
        out[0] = 0.0
        out[1] = 0.0
        out[2] = 0.0
        return _within(d, truncation)
    return d


@njit(cache=True, parallel=True)
def field_lookup(index, bricks, origin, inv_h, quantum, truncation, shift, points):
    """Signed, truncated distances ``(m,)`` of ``points (m, 3)``."""
    out = np.empty(points.shape[0])
    for i in prange(points.shape[0]):
        out[i] = _sample(index, bricks, origin, inv_h, quantum, truncation, shift,
                         points[i, 0], points[i, 1], points[i, 2])
    return out


@njit(cache=True, parallel=True)
def field_gradient(index, bricks, origin, inv_h, quantum, truncation, shift, points):
    """Signed, truncated distances ``(m,)`` of ``points (m, 3)`` and their gradients ``(m, 3)``."""
    d = np.empty(points.shape[0])
    g = np.zeros((points.shape[0], 3))
    for i in prange(points.shape[0]):
        d[i] = _sample_gradient(index, bricks, origin, inv_h, quantum, truncation, shift,
                                points[i, 0], points[i, 1], points[i, 2], g[i])
    return d, g


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


@njit(cache=True, nogil=True)
def _cholesky_solve(A, b, out):
    """``A out = b`` for a symmetric positive definite ``A (n, n)`` (Cholesky, in place on copies):
    False (``out`` zero) where a pivot is not positive."""
    n = A.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if s <= 0.0:
            for i in range(n):
                out[i] = 0.0
            return False
        L[j, j] = np.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    y = np.empty(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * out[k]
        out[i] = s / L[i, i]
    return True


@njit(cache=True, nogil=True)
def _rodrigues(w, out):
    """The rotation ``out (3, 3)`` of rotation vector ``w (3,)``."""
    theta = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if theta < 1e-300:
        for i in range(3):
            for j in range(3):
                out[i, j] = 1.0 if i == j else 0.0
        return
    kx = w[0] / theta
    ky = w[1] / theta
    kz = w[2] / theta
    s = np.sin(theta)
    c = 1.0 - np.cos(theta)
    out[0, 0] = 1.0 - c * (ky * ky + kz * kz)
    out[0, 1] = -s * kz + c * kx * ky
    out[0, 2] = s * ky + c * kx * kz
    out[1, 0] = s * kz + c * kx * ky
    out[1, 1] = 1.0 - c * (kx * kx + kz * kz)
    out[1, 2] = -s * kx + c * ky * kz
    out[2, 0] = -s * ky + c * kx * kz
    out[2, 1] = s * kx + c * ky * kz
    out[2, 2] = 1.0 - c * (kx * kx + ky * ky)


@njit(cache=True, nogil=True)
def _add_plane(y0, y1, y2, n0, n1, n2, r, J, A, b):
    """One residual ``r`` at a moved point ``y`` on a plane of unit normal ``n`` into the normal
    equations: its row ``J (6,) = (y x n, n)`` (turn, shift), the upper triangle of ``A (6, 6)``
    and ``b (6,)`` (``-J^T r``)."""
    J[0] = y1 * n2 - y2 * n1
    J[1] = y2 * n0 - y0 * n2
    J[2] = y0 * n1 - y1 * n0
    J[3] = n0
    J[4] = n1
    J[5] = n2
    for p in range(6):
        b[p] -= J[p] * r
        for q in range(p, 6):
            A[p, q] += J[p] * J[q]


@njit(cache=True, nogil=True)
def _damped_solve(A, b, out):
    """The damped step ``out (6,)`` of the normal equations ``A`` (upper triangle filled) and ``b``:
    ``A`` made symmetric, ``1e-6 (trace / 6 + 1e-12)`` added to its diagonal.  False (``out``
    zero) when ``A`` has no trace (no residual constrains the pose) or is not positive definite."""
    trace = 0.0
    for p in range(6):
        trace += A[p, p]
        for q in range(p):
            A[p, q] = A[q, p]
    if trace <= 0.0:
        for p in range(6):
            out[p] = 0.0
        return False
    damp = 1e-6 * (trace / 6.0 + 1e-12)
    for p in range(6):
        A[p, p] += damp
    return _cholesky_solve(A, b, out)


@njit(cache=True, nogil=True)
def _turn(step, dR, tmp, R, t, Ro, to):
    """The pose ``R (3, 3), t (3,)`` after ``step (6,)`` (turn, shift) into ``Ro, to`` (which may be
    ``R, t``): ``dR R``, ``dR t + shift``, ``dR (3, 3)`` the turn's rotation; ``tmp (3, 3)`` scratch."""
    _rodrigues(step[:3], dR)
    for r in range(3):
        for c in range(3):
            tmp[r, c] = dR[r, 0] * R[0, c] + dR[r, 1] * R[1, c] + dR[r, 2] * R[2, c]
    t0 = dR[0, 0] * t[0] + dR[0, 1] * t[1] + dR[0, 2] * t[2] + step[3]
    t1 = dR[1, 0] * t[0] + dR[1, 1] * t[1] + dR[1, 2] * t[2] + step[4]
    t2 = dR[2, 0] * t[0] + dR[2, 1] * t[1] + dR[2, 2] * t[2] + step[5]
    for r in range(3):
        for c in range(3):
            Ro[r, c] = tmp[r, c]
    to[0] = t0
    to[1] = t1
    to[2] = t2


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
        total = 0.0
        for k in range(m):
            y0 = Ri[0, 0] * x[k, 0] + Ri[0, 1] * x[k, 1] + Ri[0, 2] * x[k, 2] + ti[0]
            y1 = Ri[1, 0] * x[k, 0] + Ri[1, 1] * x[k, 1] + Ri[1, 2] * x[k, 2] + ti[1]
            y2 = Ri[2, 0] * x[k, 0] + Ri[2, 1] * x[k, 1] + Ri[2, 2] * x[k, 2] + ti[2]
            total += abs(_sample(index, bricks, origin, inv_h, quantum, truncation, shift, y0, y1, y2))
        score[i] = total / m
    return Ro, to, score


@njit(cache=True, parallel=True)
def plane_step(R, t, moved, normals, residuals):
    """One damped point-to-plane Gauss-Newton step on each pose ``R (h, 3, 3), t (h, 3)``, given the
    moved data ``moved (h, m, 3)``, their planes' unit normals ``normals (h, m, 3)`` and signed
    distances ``residuals (h, m)`` (:func:`tactrec.registration.solver.step`).  Returns the new
    poses, the steps ``(h, 6)`` (turn, shift) and the residuals the linearisation predicts ``(h, m)``."""
    h = R.shape[0]
    m = moved.shape[1]
    Ro = np.empty_like(R)
    to = np.empty_like(t)
    delta = np.zeros((h, 6))
    after = np.empty((h, m))
    for i in prange(h):
        A = np.zeros((6, 6))
        b = np.zeros(6)
        J = np.empty((m, 6))
        dR = np.empty((3, 3))
        tmp = np.empty((3, 3))
        step = np.zeros(6)
        for k in range(m):
            _add_plane(moved[i, k, 0], moved[i, k, 1], moved[i, k, 2], normals[i, k, 0], normals[i, k, 1],
                       normals[i, k, 2], residuals[i, k], J[k], A, b)
        _damped_solve(A, b, step)                 # no constraint: a zero step, the pose unchanged
        for p in range(6):
            delta[i, p] = step[p]
        _turn(step, dR, tmp, R[i], t[i], Ro[i], to[i])
        for k in range(m):
            predicted = residuals[i, k]
            for p in range(6):
                predicted += J[k, p] * step[p]
            after[i, k] = predicted
    return Ro, to, delta, after


def warm() -> None:
    """Load every kernel's compiled code (from numba's cache, or compiling it) by calling each once on
    a tiny empty field, with the argument types and layouts a search passes."""
    from .anderson import anderson

    field = (np.full((1, 1, 1), -1, dtype=np.int32), np.zeros((1, BRICK + 1, BRICK + 1, BRICK + 1), dtype=np.int16),
             np.zeros(3), 1.0, 1.0, 1.0, 0.0)
    points = np.zeros((2, 3))
    eye = np.ascontiguousarray(np.broadcast_to(np.eye(3), (2, 3, 3)))
    field_lookup(*field, points)
    field_gradient(*field, points)
    turned = screen_rotations(points, 2)
    field_best(*field, eye, points, turned)
    field_refine(*field, eye, points, points, 1)
    plane_step(eye, points, np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), np.zeros((2, 2)))
    anderson(eye, points, eye, points, eye, points, np.zeros((2, 4, 6)), np.zeros((2, 4, 6)), np.zeros(2, dtype=np.int64),
             1.0)
