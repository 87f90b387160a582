"""Anderson acceleration of the point-to-plane solver's steps (compiled; no fastmath).

A Gauss-Newton step on a faceted surface sees each data point's plane and
not how the surface bends away from it: where the data leave a direction
weakly held (sliding along a gently curved patch), every step moves the
pose a few per cent of the way and the steps repeat, for a hundred
iterations.  Anderson acceleration (type II, as in AA-ICP: Pavlov et al.,
ICRA 2018) treats the step as a fixed-point map ``g(u)`` of the pose's
parameters and extrapolates from the last few: it solves
``min |f_k - dF gamma|`` over the differences of the residuals
``f = g(u) - u`` and moves to ``g(u_k) - dG gamma``.  The caller keeps the
extrapolation only while it lowers the error
(:func:`tactrec.registration.solver.solve`).

A pose's parameters are taken relative to where its refinement started:
``R = Q R0``, ``t = Q t0 + s`` gives ``u = (reach w, s)`` with ``w`` the
rotation vector of ``Q`` (scaled by the data's reach so that both halves
are lengths).  Every sum runs in a fixed order: the same bits on every CPU.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..compiled import fork_safe
from .step import _cholesky_solve, _rodrigues

__all__ = ["anderson"]

fork_safe()

#: a relative turn this close to a half turn (radians) has no steady rotation vector: start afresh
_HALF_TURN = np.pi - 1e-3


@njit(cache=True, nogil=True)
def _params(R0, t0, R, t, reach, out):
    """``out (6,)``: the parameters of pose ``R, t`` relative to ``R0, t0``; False past a half turn."""
    Q = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            Q[r, c] = R[r, 0] * R0[c, 0] + R[r, 1] * R0[c, 1] + R[r, 2] * R0[c, 2]
    cos = 0.5 * (Q[0, 0] + Q[1, 1] + Q[2, 2] - 1.0)
    cos = min(1.0, max(-1.0, cos))
    theta = np.arccos(cos)
    if theta > _HALF_TURN:
        return False
    k = 0.5 if theta < 1e-8 else 0.5 * theta / np.sin(theta)
    out[0] = reach * k * (Q[2, 1] - Q[1, 2])
    out[1] = reach * k * (Q[0, 2] - Q[2, 0])
    out[2] = reach * k * (Q[1, 0] - Q[0, 1])
    for r in range(3):
        out[3 + r] = t[r] - (Q[r, 0] * t0[0] + Q[r, 1] * t0[1] + Q[r, 2] * t0[2])
    return True


@njit(cache=True, nogil=True)
def _pose(R0, t0, u, reach, R, t):
    """The pose ``R, t`` of parameters ``u (6,)`` relative to ``R0, t0``."""
    w = np.empty(3)
    for r in range(3):
        w[r] = u[r] / reach
    Q = np.empty((3, 3))
    _rodrigues(w, Q)
    for r in range(3):
        for c in range(3):
            R[r, c] = Q[r, 0] * R0[0, c] + Q[r, 1] * R0[1, c] + Q[r, 2] * R0[2, c]
        t[r] = Q[r, 0] * t0[0] + Q[r, 1] * t0[1] + Q[r, 2] * t0[2] + u[3 + r]


@njit(cache=True, nogil=True)
def _mix(U, G, n, gamma):
    """The least-squares weights ``gamma (n - 1,)`` of the last ``n`` residuals ``G - U`` (rows):
    ``min |f_last - dF gamma|`` by its normal equations (a relative ridge of 1e-10,
    :func:`tactrec.registration.step._cholesky_solve`).  False where they are singular."""
    p = n - 1
    dF = np.empty((p, 6))
    for j in range(p):
        for q in range(6):
            dF[j, q] = (G[j + 1, q] - U[j + 1, q]) - (G[j, q] - U[j, q])
    A = np.empty((p, p))
    b = np.empty(p)
    trace = 0.0
    for a in range(p):
        for c in range(p):
            s = 0.0
            for q in range(6):
                s += dF[a, q] * dF[c, q]
            A[a, c] = s
        trace += A[a, a]
        s = 0.0
        for q in range(6):
            s += dF[a, q] * (G[n - 1, q] - U[n - 1, q])
        b[a] = s
    if not trace > 0.0:
        return False
    for a in range(p):
        A[a, a] += 1e-10 * trace
    return _cholesky_solve(A, b, gamma)


@njit(cache=True, parallel=True)
def anderson(R0, t0, R, t, Rg, tg, U, G, count, reach):
    """One Anderson extrapolation for each pose ``i``.

    ``R0 (h, 3, 3), t0 (h, 3)``: where each refinement started; ``R, t``: the poses the last
    step started from; ``Rg, tg``: where the plain step took them.  ``U, G (h, k, 6)`` hold each
    pose's last ``count[i]`` parameters before and after a step (oldest first; updated in place,
    the oldest dropped once ``k`` are held), ``reach`` the data's reach.  Returns the extrapolated
    poses ``(h, 3, 3), (h, 3)`` and whether each was extrapolated ``(h,) bool`` (else the plain
    step's pose, and its history restarted where its parameters are not defined)."""
    h = R.shape[0]
    k = U.shape[1]
    Ro = np.empty_like(R)
    to = np.empty_like(t)
    moved = np.zeros(h, dtype=np.bool_)
    for i in prange(h):
        u = np.empty(6)
        g = np.empty(6)
        for r in range(3):
            to[i, r] = tg[i, r]
            for c in range(3):
                Ro[i, r, c] = Rg[i, r, c]
        if not (_params(R0[i], t0[i], R[i], t[i], reach, u) and _params(R0[i], t0[i], Rg[i], tg[i], reach, g)):
            count[i] = 0
            continue
        n = count[i]
        if n == k:
            for j in range(k - 1):
                for q in range(6):
                    U[i, j, q] = U[i, j + 1, q]
                    G[i, j, q] = G[i, j + 1, q]
            n = k - 1
        for q in range(6):
            U[i, n, q] = u[q]
            G[i, n, q] = g[q]
        n += 1
        count[i] = n
        if n < 2:
            continue
        gamma = np.empty(n - 1)
        if not _mix(U[i], G[i], n, gamma):
            continue
        x = np.empty(6)
        for q in range(6):
            s = g[q]
            for j in range(n - 1):
                s -= (G[i, j + 1, q] - G[i, j, q]) * gamma[j]
            x[q] = s
        finite = True
        for q in range(6):
            finite = finite and np.isfinite(x[q])
        if finite:
            _pose(R0[i], t0[i], x, reach, Ro[i], to[i])
            moved[i] = True
    return Ro, to, moved
