"""Registration onto a closed-form surface, as in the paper (Section 4.2).

The data points are expressed in a local frame at the contact point ``p``
(``x' = [t1 t2 N]^T (x - p)``) and placed on the model at ``q = sigma(u, v)``
with frame ``[d1 d2 n]`` and a rotation ``phi`` about the normal::

    x'' = [d1 d2 n] Rz(phi) x' + q

The superposition error is the mean first-order distance (eq. 11)::

    E(u, v, phi) = (1/n) sum_i |f(x''_i)| / |grad f(x''_i)|

From every candidate (Section 4.2.1): the initial ``phi`` by scanning
``[0, 2 pi)`` and bisecting on ``dE/dphi`` inside each bracket around a
local minimum; then steepest descent on ``(u, v, phi)`` with the analytic
gradient of (11), each step a line search along ``-grad E``, until ``E`` no
longer decreases or 100 steps are done (Section 4.2.2).  The registration
error is the smallest local minimum (eq. 12).

Everything is batched over candidates.  Steepest descent works in the
surface's metric (u scaled by ``|sigma_u|``, v by ``|sigma_v|``, phi by the
data's radius), so one step length means the same on every parametrisation.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..compiled import fork_safe
from ..estimation import LocalGeometry
from ..linalg import compose, rotate, times
from ..surfaces.closedform import ClosedFormSurface
from ..tables import CurvatureTable
from .result import Registration, local_frame, rotations_z

__all__ = ["register", "Superposition", "DEFAULTS"]

fork_safe()

DEFAULTS = {
    "delta": 0.2,           # lookup tolerance, 1/model units (eq. 7)
    "phi_samples": 36,      # scan of [0, 2 pi) for the initial phi
    "bisections": 15,
    "max_iterations": 100,
    "chunk_points": 400_000,  # points evaluated at once (memory bound)
}


class Superposition:
    """E(u, v, phi) of eq. (11) and its gradient, batched over parameter points.

    Parameters
    ----------
    model : ClosedFormSurface
    local : (n, 3) float
        Data points in the local frame at ``p`` (``x'``).
    """

    def __init__(self, model: ClosedFormSurface, local: np.ndarray):
        self.model = model
        self.local = np.asarray(local, dtype=np.float64)
        self.radius = float(np.sqrt(np.mean(np.sum(self.local[:, :2] ** 2, axis=1)))) or 1.0

    def _rotated(self, phi, turning: bool = True):
        """The data turned by ``phi (m,)`` ``(m, n, 3)`` and (``turning``; else None) its derivative in phi."""
        c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
        x, y, z = self.local[:, 0], self.local[:, 1], self.local[:, 2]
        w = np.stack([c * x - s * y, s * x + c * y, np.broadcast_to(z, c.shape[:1] + z.shape)], axis=-1)
        if not turning:
            return w, None
        w_phi = np.stack([-s * x - c * y, c * x - s * y, np.zeros(c.shape[:1] + z.shape)], axis=-1)
        return w, w_phi

    def transform(self, uv: np.ndarray, phi: np.ndarray, turning: bool = True):
        """Model-frame points ``(m, n, 3)`` for parameters ``uv (m, 2)``, ``phi (m,)``, the surface's
        frame jet and the turned data with (``turning``) its derivative in phi."""
        jet = self.model.frame_jet(uv[:, 0], uv[:, 1])
        w, w_phi = self._rotated(phi, turning)
        X = _apply(jet.frame, w) + jet.point[:, None, :]
        return X, jet, w, w_phi

    def _chunks(self, m: int):
        step = max(1, DEFAULTS["chunk_points"] // max(1, len(self.local)))
        return [slice(i, min(m, i + step)) for i in range(0, m, step)]

    def energy(self, uv: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """E of eq. (11), shape ``(m,)``; ``inf`` at singular parameter points."""
        out = np.empty(len(phi))
        for sl in self._chunks(len(phi)):
            X, jet, _, _ = self.transform(uv[sl], phi[sl], turning=False)
            fg = self.model.implicit(X, order=1)
            with np.errstate(all="ignore"):
                g = np.abs(fg[..., 0]) / np.linalg.norm(fg[..., 1:], axis=-1)
            e = g.mean(axis=1)
            out[sl] = np.where(jet.regular & np.isfinite(e), e, np.inf)
        return out

    def energy_grad(self, uv: np.ndarray, phi: np.ndarray, turn_only: bool = False):
        """E ``(m,)``, its gradient ``(m, 3)`` in (u, v, phi) and the metric
        scales ``(m, 3)`` (``|sigma_u|, |sigma_v|``, data radius); ``turn_only``: the gradient in phi
        alone (the others 0), as :meth:`initial_phi`'s bisection reads it."""
        m = len(phi)
        E = np.empty(m)
        G = np.empty((m, 3))
        S = np.empty((m, 3))
        for sl in self._chunks(m):
            X, jet, w, w_phi = self.transform(uv[sl], phi[sl], turning=not turn_only)
            v = self.model.implicit(X, order=2)
            if turn_only:                   # the bisection's derivative in one compiled pass (no temporaries)
                e, turn = _turn(v, jet.frame, self.local, phi[sl])
                grads = [np.zeros_like(turn), np.zeros_like(turn), turn]
            else:
                e, grads = self._gradient(v, jet, w, w_phi)
            ok = jet.regular & np.isfinite(e)
            E[sl] = np.where(ok, e, np.inf)
            G[sl] = np.where(ok[:, None], np.stack(grads, axis=1), 0.0)
            S[sl, 0] = np.linalg.norm(jet.su, axis=-1)
            S[sl, 1] = np.linalg.norm(jet.sv, axis=-1)
            S[sl, 2] = self.radius
        G[~np.isfinite(G)] = 0.0
        return E, G, S

    def _gradient(self, v: np.ndarray, jet, w: np.ndarray, w_phi: np.ndarray):
        """E ``(m,)`` and its gradient in (u, v, phi) as three ``(m,)`` arrays, from the implicit function's
        value, gradient and Hessian at the turned points ``v (m, n, 10)`` (:meth:`energy_grad`)."""
        f, gx, gy, gz = v[..., 0], v[..., 1], v[..., 2], v[..., 3]
        hxx, hxy, hxz, hyy, hyz, hzz = (v[..., 4 + i] for i in range(6))
        with np.errstate(all="ignore"):
            gn = np.sqrt(gx * gx + gy * gy + gz * gz)
            g = f / gn
            c = f / gn**3
            # d/dx (f / |grad f|) = grad f / |grad f| - f H grad f / |grad f|^3, times sign(g)
            sign = np.sign(g)
            dg = np.stack([gx / gn - c * (hxx * gx + hxy * gy + hxz * gz),
                           gy / gn - c * (hxy * gx + hyy * gy + hyz * gz),
                           gz / gn - c * (hxz * gx + hyz * gy + hzz * gz)], axis=-1) * sign[..., None]
        n_inv = 1.0 / len(self.local)
        turn = np.einsum("mni,mni->m", dg, _apply(jet.frame, w_phi)) * n_inv
        return np.abs(g).mean(axis=1), [
            np.einsum("mni,mni->m", dg, _apply(jet.frame_u, w) + jet.su[:, None, :]) * n_inv,
            np.einsum("mni,mni->m", dg, _apply(jet.frame_v, w) + jet.sv[:, None, :]) * n_inv, turn]

    # ------------------------------------------------------------------ phi
    def initial_phi(self, uv: np.ndarray, *, samples: int, bisections: int):
        """Best initial phi per candidate: scan, then bisect on dE/dphi in each bracket."""
        c = len(uv)
        phis = 2 * np.pi * np.arange(samples) / samples
        uv_rep = np.repeat(uv, samples, axis=0)
        E = self.energy(uv_rep, np.tile(phis, c)).reshape(c, samples)
        left, right = np.roll(E, 1, axis=1), np.roll(E, -1, axis=1)
        is_min = (E <= left) & (E <= right) & np.isfinite(E)
        ci, ki = np.nonzero(is_min)
        if len(ci) == 0:
            return np.zeros(c), np.full(c, np.inf)
        step = 2 * np.pi / samples
        lo = phis[ki] - step
        hi = phis[ki] + step
        uv_b = uv[ci]
        for _ in range(bisections):
            mid = 0.5 * (lo + hi)
            _, G, _ = self.energy_grad(uv_b, mid, turn_only=True)
            up = G[:, 2] > 0
            hi = np.where(up, mid, hi)
            lo = np.where(up, lo, mid)
        phi_b = 0.5 * (lo + hi)
        E_b = self.energy(uv_b, phi_b)
        # bisection can only improve on the bracket's sample
        worse = ~(E_b <= E[ci, ki])
        phi_b[worse] = phis[ki[worse]]
        E_b[worse] = E[ci[worse], ki[worse]]
        best_phi = np.zeros(c)
        best_E = np.full(c, np.inf)
        order = np.argsort(E_b)[::-1]          # write the smallest last
        best_phi[ci[order]] = phi_b[order]
        best_E[ci[order]] = E_b[order]
        return best_phi, best_E

    # ------------------------------------------------------------------ descent
    def descend(self, uv: np.ndarray, phi: np.ndarray, *, max_iterations: int, step0: float | None = None):
        """Batched steepest descent on (u, v, phi) until E stops decreasing.

        Each iteration searches along ``-grad E`` (in the surface's metric)
        at the steps ``alpha * 2^j``, ``j = -2..3``, and moves to the best
        one; without a decrease, ``alpha`` shrinks eightfold.  A search ends
        when ``alpha`` falls below 1e-4 of the data's radius.
        """
        uv = self.model.wrap(np.array(uv, dtype=np.float64))
        phi = np.array(phi, dtype=np.float64)
        E, G, S = self.energy_grad(uv, phi)
        alpha = np.full(len(phi), step0 if step0 is not None else 0.05 * self.radius)
        min_alpha = 1e-4 * self.radius
        factors = 2.0 ** np.arange(-2, 4)
        nf = len(factors)
        active = np.isfinite(E)
        for _ in range(max_iterations):
            a = np.nonzero(active)[0]
            if len(a) == 0:
                break
            g_eta = G[a] / S[a]
            norm = np.linalg.norm(g_eta, axis=1)
            flat = norm == 0
            direction = -(g_eta / np.where(flat, 1.0, norm)[:, None]) / S[a]          # (k, 3)
            steps = alpha[a, None] * factors[None, :]                                  # (k, f)
            trial = np.concatenate([uv[a], phi[a, None]], axis=1)[:, None, :] + steps[..., None] * direction[:, None, :]
            trial = trial.reshape(-1, 3)
            uv_t = self.model.wrap(trial[:, :2])
            E_t = self.energy(uv_t, trial[:, 2]).reshape(-1, nf)
            j = np.argmin(E_t, axis=1)
            E_best = E_t[np.arange(len(a)), j]
            better = (E_best < E[a] * (1.0 - 1e-6)) & ~flat
            good = a[better]
            if len(good):
                pick = np.nonzero(better)[0] * nf + j[better]
                uv[good] = uv_t[pick]
                phi[good] = trial[pick, 2]
                E[good], G[good], S[good] = self.energy_grad(uv[good], phi[good])
                alpha[good] = steps[better, j[better]]
            bad = a[~better]
            alpha[bad] /= 8.0
            active[bad[(alpha[bad] < min_alpha) | flat[~better]]] = False
        return uv, np.mod(phi, 2 * np.pi), E


@njit(cache=True, parallel=True, error_model="numpy")
def _turn(v: np.ndarray, frame: np.ndarray, local: np.ndarray, phi: np.ndarray):
    """E of eq. (11) ``(m,)`` and its derivative in phi ``(m,)`` from the implicit function's value,
    gradient and Hessian at each turned point ``v (m, n, 10)``, the frames ``(m, 3, 3)``, the data
    ``local (n, 3)`` and the turns ``phi (m,)``: :meth:`Superposition.energy_grad`'s formulas, each
    candidate's sums taken over its points in order."""
    m, n = v.shape[0], v.shape[1]
    e = np.empty(m)
    turn = np.empty(m)
    for a in prange(m):
        c, s = np.cos(phi[a]), np.sin(phi[a])
        total, slope = 0.0, 0.0
        for b in range(n):
            f, gx, gy, gz = v[a, b, 0], v[a, b, 1], v[a, b, 2], v[a, b, 3]
            hxx, hxy, hxz, hyy, hyz, hzz = v[a, b, 4], v[a, b, 5], v[a, b, 6], v[a, b, 7], v[a, b, 8], v[a, b, 9]
            gn = np.sqrt(gx * gx + gy * gy + gz * gz)
            g = f / gn
            k = f / gn**3
            sign = np.sign(g)
            x, y = local[b, 0], local[b, 1]
            px, py = -s * x - c * y, c * x - s * y                  # d/dphi of the turned point (z: 0)
            qx = frame[a, 0, 0] * px + frame[a, 0, 1] * py
            qy = frame[a, 1, 0] * px + frame[a, 1, 1] * py
            qz = frame[a, 2, 0] * px + frame[a, 2, 1] * py
            slope += sign * ((gx / gn - k * (hxx * gx + hxy * gy + hxz * gz)) * qx
                             + (gy / gn - k * (hxy * gx + hyy * gy + hyz * gz)) * qy
                             + (gz / gn - k * (hxz * gx + hyz * gy + hzz * gz)) * qz)
            total += abs(g)
        e[a] = total / n
        turn[a] = slope / n
    return e, turn


@njit(cache=True, parallel=True)
def _apply(frame: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``frame[m] @ w[m, n]`` for ``frame (m, 3, 3)`` and ``w (m, n, 3)``: each entry's three products
    summed left to right, as numpy's element-wise form does (the same bits; compiled, as the
    descent's arrays make it its costliest step)."""
    m, n = w.shape[0], w.shape[1]
    out = np.empty((m, n, 3))
    for a in prange(m):
        for b in range(n):
            for i in range(3):
                out[a, b, i] = frame[a, i, 0] * w[a, b, 0] + frame[a, i, 1] * w[a, b, 1] + frame[a, i, 2] * w[a, b, 2]
    return out


def register(model: ClosedFormSurface, table: CurvatureTable, geometry: LocalGeometry, points: np.ndarray, *,
             delta: float = DEFAULTS["delta"], phi_samples: int = DEFAULTS["phi_samples"],
             bisections: int = DEFAULTS["bisections"], max_iterations: int = DEFAULTS["max_iterations"],
             candidates: np.ndarray | None = None, **_ignored) -> Registration:
    """Register data ``points`` ``(n, 3)`` onto ``model`` from the lookup candidates.

    ``geometry`` gives the contact point, the (oriented) data normal and the
    principal curvatures used for the lookup (eq. 7, tolerance ``delta``).
    ``candidates`` (table rows) overrides the lookup.
    """
    idx = table.candidates(geometry.k1, geometry.k2, delta) if candidates is None else np.asarray(candidates)
    if len(idx) == 0:
        return Registration.unfitted(model.name, "no candidates")
    L = local_frame(geometry.normal, geometry.directions[0])
    local = times(np.asarray(points, dtype=np.float64) - geometry.contact, L.T)
    problem = Superposition(model, local)
    uv0 = table.samples.sites[idx]
    phi0, _ = problem.initial_phi(uv0, samples=phi_samples, bisections=bisections)
    uv, phi, E = problem.descend(uv0, phi0, max_iterations=max_iterations)
    best = int(np.argmin(E))
    if not np.isfinite(E[best]):
        return Registration.unfitted(model.name, "registration failed")
    jet = model.frame_jet(uv[best:best + 1, 0], uv[best:best + 1, 1])
    R = compose(compose(jet.frame[0], rotations_z(phi[best:best + 1])[0]), L)
    q = jet.point[0]
    return Registration(model=model.name, error=float(E[best]), location=q, rotation=R,
                        translation=q - rotate(R, geometry.contact), candidates=len(idx), site=uv[best],
                        phi=float(phi[best]))
