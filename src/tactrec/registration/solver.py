"""The one point-to-plane solver: damped Gauss-Newton on poses, for every surface model.

Every refinement of a pose in ``fast`` (a touch's search, a session's joint
fit, its pose families) and the information matrices of ``next``
(:mod:`tactrec.proposal`) linearise the same residuals: the signed
distances of the moved data points to the planes the model gives them
(:meth:`planes` of a surface model: a mesh's closest-point planes, a
closed-form surface's first-order distances ``f / |grad f|``, eq. 11).  A
small turn ``w`` about the origin and a shift ``v`` of the model frame move
each residual by ``(y x n) . w + n . v`` (:func:`.step.jacobian`).

The arithmetic is element-wise (:mod:`tactrec.linalg`) or a compiled
kernel's fixed-order loops (:mod:`.step`: the one Jacobian and the one
damping rule, no fused or reordered operations): the same bits on every CPU.  The paper's own
registrations (:mod:`.closedform_paper`, :mod:`.mesh_paper`) keep the
paper's steps.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..linalg import cross, transform

__all__ = ["Criteria", "Fit", "step", "solve", "mean_distance"]


@dataclasses.dataclass(frozen=True)
class Criteria:
    """When a refinement stops: after ``iterations`` steps, or for a pose once no data point moves by
    more than ``tolerance`` x the data's reach (its largest distance from its centroid).  With
    ``predict``, the errors returned are those the last step's linearisation predicts, which
    spares a last query of every point.  ``history`` > 0 accelerates the steps by Anderson's
    extrapolation from that many past steps (:mod:`.anderson`)."""

    iterations: int
    tolerance: float = 1e-5
    predict: bool = False
    history: int = 0

    def __post_init__(self):
        if not isinstance(self.iterations, (int, np.integer)) or self.iterations < 0:
            raise ValueError(f"iterations must be a whole number >= 0, got {self.iterations!r}")
        if not isinstance(self.history, (int, np.integer)) or self.history < 0:
            raise ValueError(f"history must be a whole number >= 0, got {self.history!r}")
        if not (np.isfinite(self.tolerance) and self.tolerance >= 0):
            raise ValueError(f"tolerance must be a number >= 0, got {self.tolerance!r}")


@dataclasses.dataclass(frozen=True)
class Fit:
    """Refined poses ``R (h, 3, 3), t (h, 3)``, their mean distances ``error (h,)`` (model units; inf
    where the model gives no plane) and the distance queries made (``queries``)."""

    R: np.ndarray
    t: np.ndarray
    error: np.ndarray
    queries: int

    def __iter__(self):
        """``R, t, error, queries``, so that a fit unpacks like a tuple."""
        return iter((self.R, self.t, self.error, self.queries))



def step(R: np.ndarray, t: np.ndarray, moved: np.ndarray, normals: np.ndarray, residuals: np.ndarray):
    """One damped Gauss-Newton (Levenberg-Marquardt) step on poses ``R (h, 3, 3), t (h, 3)``.

    ``moved (h, m, 3)`` are the data points under the poses, ``normals (h, m, 3)`` the unit
    normals of their planes and ``residuals (h, m)`` their signed distances.  The damping keeps
    directions that a flat or cylindrical patch leaves unconstrained from running away.  Returns
    the new poses, the steps ``(h, 6)`` and the residuals the linearisation predicts after them
    ``(h, m)``."""
    from .step import plane_step         # compiled: the steps of every pose at once

    c = np.ascontiguousarray
    return plane_step(c(R, dtype=np.float64), c(t, dtype=np.float64), c(moved, dtype=np.float64),
                      c(normals, dtype=np.float64), c(residuals, dtype=np.float64))


def mean_distance(model, R: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Exact mean distance ``(h,)`` to ``model`` of ``x (m, 3)`` under each pose ``R (h, 3, 3), t (h, 3)``
    (inf where the model's distance is not finite)."""
    with np.errstate(all="ignore"):
        d = model.distance(transform(R, t, x).reshape(-1, 3)).reshape(len(R), -1).mean(axis=1)
    return np.where(np.isfinite(d), d, np.inf)


def solve(model, R: np.ndarray, t: np.ndarray, x: np.ndarray, criteria: Criteria) -> Fit:
    """Refine poses ``R (h, 3, 3), t (h, 3)`` of data ``x (m, 3)`` onto ``model`` (model units) by
    :func:`step`, each pose stopping on its own (``criteria``), so that a pose refined in a batch
    takes the steps it would take alone.  A pose whose planes are not finite (a closed-form
    surface's singular point) stops where it is.

    With ``criteria.history``, each step after the first is extrapolated (:class:`_Anderson`);
    an extrapolation whose error is not below that of the pose it came from is undone (the pose
    goes back to where the plain step took it, its history restarted), and a pose ends on a
    plain step's pose, so that the errors returned (or predicted) are that pose's."""
    R, t = np.array(R, dtype=np.float64), np.array(t, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    reach = float(np.max(np.linalg.norm(x - x.mean(axis=0), axis=1))) if len(x) else 0.0
    predicted = np.full((len(R), len(x)), np.inf) if criteria.predict else None
    speed = _Anderson(R, t, criteria.history, reach) if criteria.history > 0 and reach > 0 else None
    active = np.arange(len(R))
    queries = 0
    for k in range(criteria.iterations):
        if len(active) == 0:
            break
        moved = transform(R[active], t[active], x)                                       # (a, m, 3)
        residual, n = model.planes(moved)
        queries += moved.shape[0] * moved.shape[1]
        if speed is not None:
            back = speed.undo(active, residual)
            if len(back):
                R[active[back]], t[active[back]] = speed.plain(active[back])
                moved[back] = transform(R[active[back]], t[active[back]], x)
                residual[back], n[back] = model.planes(moved[back])
                queries += len(back) * moved.shape[1]
        finite = np.all(np.isfinite(residual), axis=1) & np.all(np.isfinite(n), axis=(1, 2))
        active, moved, residual, n = active[finite], moved[finite], residual[finite], n[finite]
        before = (R[active], t[active]) if speed is not None else None          # where the steps start from
        R[active], t[active], delta, after = step(R[active], t[active], moved, n, residual)
        if criteria.predict:
            predicted[active] = after
        w, v = delta[:, :3], delta[:, 3:]
        moves = np.linalg.norm(cross(w, moved.mean(axis=1)) + v, axis=1) + np.linalg.norm(w, axis=1) * reach
        going = moves > criteria.tolerance * reach
        if speed is not None and k + 1 < criteria.iterations and going.any():
            ahead = active[going]
            R[ahead], t[ahead] = speed.extrapolate(ahead, before[0][going], before[1][going], R[ahead], t[ahead],
                                                   np.abs(residual[going]).mean(axis=1))
        active = active[going]
    if criteria.predict and criteria.iterations > 0:
        error = np.abs(predicted).mean(axis=1)
        return Fit(R, t, np.where(np.isfinite(error), error, np.inf), int(queries))
    return Fit(R, t, mean_distance(model, R, t, x), int(queries + len(R) * len(x)))


class _Anderson:
    """The acceleration state of a batch of poses (:func:`.anderson.anderson`): where
    each started, its history, the plain step's pose and the error it was extrapolated from."""

    def __init__(self, R: np.ndarray, t: np.ndarray, history: int, reach: float):
        h = len(R)
        self.R0, self.t0, self.reach = R.copy(), t.copy(), reach
        self.U, self.G = np.zeros((h, history + 1, 6)), np.zeros((h, history + 1, 6))
        self.count = np.zeros(h, dtype=np.int64)
        self.Rg, self.tg = R.copy(), t.copy()
        self.error = np.full(h, np.inf)
        self.ahead = np.zeros(h, dtype=bool)

    def undo(self, active: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """Which of the poses ``active`` were extrapolated to an error ``(a, m)`` not below the one
        they came from (positions in ``active``); their history is restarted."""
        back = np.flatnonzero(self.ahead[active] & ~(np.abs(residual).mean(axis=1) < self.error[active]))
        self.count[active[back]] = 0
        self.ahead[active] = False
        return back

    def plain(self, which: np.ndarray):
        """The plain step's poses of ``which``."""
        return self.Rg[which], self.tg[which]

    def extrapolate(self, which, R, t, Rg, tg, error):
        """Poses ``which`` stepped from ``R, t`` (at ``error``) to ``Rg, tg``: their extrapolations."""
        from .anderson import anderson          # compiled

        c = np.ascontiguousarray
        U, G, count = c(self.U[which]), c(self.G[which]), c(self.count[which])
        Ro, to, ahead = anderson(c(self.R0[which]), c(self.t0[which]), c(R), c(t), c(Rg), c(tg), U, G, count,
                                 self.reach)
        self.U[which], self.G[which], self.count[which] = U, G, count
        self.Rg[which], self.tg[which], self.error[which], self.ahead[which] = Rg, tg, error, ahead
        return Ro, to
