"""The point-to-plane step, compiled: one Jacobian, one damping rule (numba; cached, no fastmath).

Every refinement of a pose linearises the signed distances of the moved data
points to the planes the model gives them (:mod:`tactrec.registration.solver`):
a small turn ``w`` about the origin and a shift ``v`` of the model frame move
each residual by ``(y x n) . w + n . v`` (:func:`_row`, the one Jacobian;
:func:`jacobian` for callers in numpy).  The normal equations of a step are
damped by one rule (:func:`_damp`: :data:`STEP` ``(trace / 6 + 1e-12)`` added
to the diagonal; a covariance damps at a thousandth of that, :data:`SPREAD`), which
keeps directions that a flat or cylindrical patch leaves unconstrained from running
away.  The information of a pose (:func:`normal_matrix`), its covariance
(:func:`covariance`: how well the data pin a contact) and the steps against
earlier touches' information (:func:`prior_steps`: ``next``'s refits) are built of
the same pieces.  The exact steps (:func:`plane_step`), the
engine's steps on a distance field (:func:`tactrec.engine.kernels.field_refine`)
and the acceleration of both (:mod:`.anderson`) are built of these.  Each pose
sums its points in a fixed order, in double precision, with no fused or
reordered arithmetic: the same bits on every CPU.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..compiled import fork_safe

__all__ = ["plane_step", "prior_steps", "normal_matrix", "covariance", "jacobian", "STEP", "SPREAD"]

fork_safe()

#: the damping of a step (:func:`_damp`): it holds the directions a flat or cylindrical patch leaves
#: unconstrained, and moves the others by a millionth of the least-squares step at most
STEP = 1e-6
#: the damping of a pose's covariance (:func:`covariance`): a direction no residual constrains reads
#: as free (an inverse a thousand times the step's damping allows); at :data:`STEP`, 4 of 40 P3 and
#: hard touches of the ``paper-fig11`` scans whose contact the data leave free (along a handle, a
#: cylinder's side) read as located
SPREAD = 1e-9


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
def _row(y0, y1, y2, n0, n1, n2, J):
    """The point-to-plane Jacobian: the row ``J (6,) = (y x n, n)`` of a residual at a moved point
    ``y`` on a plane of unit normal ``n``, for a small turn ``w`` about the origin and a shift ``v``
    of the model frame (the residual moves by ``(y x n) . w + n . v``)."""
    J[0] = y1 * n2 - y2 * n1
    J[1] = y2 * n0 - y0 * n2
    J[2] = y0 * n1 - y1 * n0
    J[3] = n0
    J[4] = n1
    J[5] = n2


@njit(cache=True, nogil=True)
def _add_plane(y0, y1, y2, n0, n1, n2, r, J, A, b):
    """One residual ``r`` at a moved point ``y`` on a plane of unit normal ``n`` into the normal
    equations: its row ``J (6,)`` (:func:`_row`), the upper triangle of ``A (6, 6)`` and ``b (6,)``
    (``-J^T r``)."""
    _row(y0, y1, y2, n0, n1, n2, J)
    for p in range(6):
        b[p] -= J[p] * r
        for q in range(p, 6):
            A[p, q] += J[p] * J[q]


@njit(cache=True, nogil=True)
def _rows(moved, normals, out):
    """:func:`_row` of each of the points ``moved (n, 3)`` on planes ``normals (n, 3)`` into ``out (n, 6)``."""
    for k in range(moved.shape[0]):
        _row(moved[k, 0], moved[k, 1], moved[k, 2], normals[k, 0], normals[k, 1], normals[k, 2], out[k])


@njit(cache=True, nogil=True)
def _damp(A, rate):
    """The one damping rule: ``A (6, 6)`` made symmetric from its upper triangle and ``rate (trace / 6
    + 1e-12)`` added to its diagonal, in place.  Returns the trace (0 or less: no residual
    constrains the pose, and nothing is added)."""
    trace = 0.0
    for p in range(6):
        trace += A[p, p]
        for q in range(p):
            A[p, q] = A[q, p]
    if trace > 0.0:
        damp = rate * (trace / 6.0 + 1e-12)
        for p in range(6):
            A[p, p] += damp
    return trace


@njit(cache=True, nogil=True)
def _damped_solve(A, b, out):
    """The damped step ``out (6,)`` of the normal equations ``A`` (upper triangle filled) and ``b``:
    :func:`_damp` at :data:`STEP`.  False (``out`` zero) when ``A`` has no trace (no residual
    constrains the pose) or is not positive definite."""
    if _damp(A, STEP) <= 0.0:
        for p in range(6):
            out[p] = 0.0
        return False
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

@njit(cache=True, nogil=True)
def normal_matrix(moved, normals):
    """``J^T J (6, 6)`` of the residuals at points ``moved (m, 3)`` on planes ``normals (m, 3)`` (the
    information of a pose), summed in the points' order."""
    A = np.zeros((6, 6))
    b = np.zeros(6)
    J = np.empty(6)
    for k in range(moved.shape[0]):
        _add_plane(moved[k, 0], moved[k, 1], moved[k, 2], normals[k, 0], normals[k, 1], normals[k, 2], 0.0, J, A, b)
    for p in range(6):
        for q in range(p):
            A[p, q] = A[q, p]
    return A


@njit(cache=True, nogil=True)
def covariance(moved, normals):
    """``(J^T J)^-1 (6, 6)`` of the residuals at points ``moved (m, 3)`` on planes ``normals (m, 3)``,
    damped at :data:`SPREAD`: a pose's covariance per unit of the residuals' variance (zero where no
    residual constrains it)."""
    A = normal_matrix(moved, normals)
    out = np.zeros((6, 6))
    if _damp(A, SPREAD) <= 0.0:
        return out
    e = np.zeros(6)
    column = np.empty(6)
    for j in range(6):
        e[j] = 1.0
        if not _cholesky_solve(A, e, column):
            return np.zeros((6, 6))
        for i in range(6):
            out[i, j] = column[i]
        e[j] = 0.0
    return out


@njit(cache=True, parallel=True)
def prior_steps(H0, moved, normals, residuals, weights):
    """One damped step (:func:`_damped_solve`) of one pose for each of ``n`` sets of points, each set's
    residuals with the information ``H0 (6, 6)`` of earlier points at their optimum: ``(H0 + J^T W
    J) d = -J^T W r`` for the points ``moved (n, k, 3)`` on planes ``normals (n, k, 3)`` with signed
    distances ``residuals (n, k)`` and weights ``weights (n, k)`` (1 a point, 0 none).  Returns the
    steps ``(n, 6)``, each set's residuals after its step ``(n, k)`` (0 where not weighed) and the sum
    of squares each step adds to the earlier points, ``d^T H0 d`` ``(n,)``."""
    n = moved.shape[0]
    k = moved.shape[1]
    steps = np.zeros((n, 6))
    after = np.zeros((n, k))
    added = np.zeros(n)
    for i in prange(n):
        A = np.empty((6, 6))
        for p in range(6):
            for q in range(6):
                A[p, q] = H0[p, q]
        b = np.zeros(6)
        J = np.empty((k, 6))
        step = np.zeros(6)
        for j in range(k):
            w = weights[i, j]
            y0, y1, y2 = moved[i, j, 0], moved[i, j, 1], moved[i, j, 2]
            _row(y0, y1, y2, normals[i, j, 0] * w, normals[i, j, 1] * w, normals[i, j, 2] * w, J[j])
            r = residuals[i, j] * w
            for p in range(6):
                b[p] -= J[j, p] * r
                for q in range(p, 6):
                    A[p, q] += J[j, p] * J[j, q]
        _damped_solve(A, b, step)
        for j in range(k):
            predicted = residuals[i, j] * weights[i, j]
            for p in range(6):
                predicted += J[j, p] * step[p]
            after[i, j] = predicted
        total = 0.0
        for p in range(6):
            for q in range(6):
                total += step[p] * H0[p, q] * step[q]
        added[i] = total
        for p in range(6):
            steps[i, p] = step[p]
    return steps, after, added


def jacobian(moved: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """The residuals' derivatives ``(..., 6)`` at points ``moved (..., 3)`` with plane normals
    ``normals (..., 3)``: :func:`_row` of each, ``(y x n, n)``."""
    shape = np.broadcast_shapes(np.shape(moved), np.shape(normals))
    y = np.ascontiguousarray(np.broadcast_to(moved, shape), dtype=np.float64).reshape(-1, 3)
    n = np.ascontiguousarray(np.broadcast_to(normals, shape), dtype=np.float64).reshape(-1, 3)
    out = np.empty((len(y), 6))
    _rows(y, n, out)
    return out.reshape(shape[:-1] + (6,))
