"""Step 2 of a session (:mod:`tactrec.session.core`): one model's candidate poses scored on every touch,
the best refined jointly.  A stage of the recognizer's runner (:class:`tactrec.recognition.Recognizer`),
so the models of a session are fitted in its worker processes, each model's arithmetic the same in
any process.

Each touch is measured against the model offset by its own tip (:mod:`tactrec.tip`, (b)): touches of
different tips fit one pose, each against its own offset."""

from __future__ import annotations

import numpy as np

from ..registration.solver import Criteria, mean_distance, solve
from ..tip import offset

__all__ = ["refine", "per_touch", "fit_stage", "JOINT_ITERATIONS", "REFINED", "HISTORY"]

#: Gauss-Newton steps of a joint refinement, and how many candidate poses per model are refined
JOINT_ITERATIONS, REFINED = 15, 2
#: past steps a refinement's step is extrapolated from (Anderson acceleration, as method ``fast``'s)
HISTORY = 3


def refine(model, R: np.ndarray, t: np.ndarray, x: np.ndarray, iterations: int):
    """Poses ``R (h, 3, 3), t (h, 3)`` refined on points ``x (m, 3)`` (model units) by the one
    point-to-plane solver (:func:`tactrec.registration.solver.solve`, accelerated from :data:`HISTORY`
    steps): ``R, t``.  Its callers score the poses per touch (:func:`per_touch`), so the solver
    predicts its last errors rather than querying every point once more."""
    fit = solve(model, R, t, x, Criteria(iterations, predict=True, history=HISTORY))
    return fit.R, fit.t


def per_touch(model, R: np.ndarray, t: np.ndarray, points: list, scale: float, tips=None) -> np.ndarray:
    """Mean distance of each touch's points ``points[i] (m_i, 3)`` (data units) under poses
    ``R (h, 3, 3), t (h, 3)``: ``(h, N)``, data units (inf where the model gives no distance); each
    touch against the model offset by its tip ``tips[i]`` (data units; None: none)."""
    tips = np.zeros(len(points)) if tips is None else tips
    return np.stack([mean_distance(offset(model, r * scale), R, t, x * scale) / scale
                     for x, r in zip(points, tips)], axis=1)


def joint_model(model, points: list, tips, scale: float, use=None):
    """``model`` offset by the tip of each point of the touches ``points`` used (``use``: a flag per
    touch, None: all), concatenated in order; ``tips`` per touch (data units; None: none)."""
    if tips is None or not np.any(tips):
        return model
    use = np.ones(len(points), dtype=bool) if use is None else np.asarray(use, dtype=bool)
    return offset(model, np.concatenate([np.full(len(p), r * scale) for p, r, u in zip(points, tips, use) if u]))


def fit_stage(held, indices, points: list, weight: np.ndarray, tips, items: list) -> list:
    """Per model at ``indices``, its candidate poses ``items[k] = (R (h, 3, 3), t (h, 3), scale)``
    scored on every touch (``points[i] (m_i, 3)``: touch ``i``'s points, data units), ranked by the
    mean distances summed over the touches weighted by ``weight (N,)`` (points a touch, 0 for a
    touch left out), the best :data:`REFINED` refined on every point of the touches weighted
    (:data:`JOINT_ITERATIONS` steps); ``tips``: each touch's tip radius (data units; None: none).  Returns per model a list of ``(R (3, 3), t (3,), per (N,))``,
    a refined pose or its start when refining did not lower the weighted sum."""
    used = np.concatenate([p for p, w in zip(points, weight) if w > 0])
    out = []
    for index, (R, t, scale) in zip(indices, items):
        model = held.entries[index].model
        per = per_touch(model, R, t, points, scale, tips)                                # (h, N)
        x = used * scale
        joint = joint_model(model, points, tips, scale, weight > 0)
        total = (per * weight).sum(axis=1)                  # element-wise: no BLAS kernel in the ranking
        best = np.argsort(total, kind="stable")[:REFINED]
        # one batch: every pose's steps and stopping are its own, as if refined alone
        Rb, tb = refine(joint, R[best], t[best], x, JOINT_ITERATIONS)
        per_b = per_touch(model, Rb, tb, points, scale, tips)
        fitted = []
        for j, k in enumerate(best):
            if (per_b[j] * weight).sum() <= total[k]:
                fitted.append((Rb[j], tb[j], per_b[j]))
            else:                                                               # keep the start if not better
                fitted.append((R[k], t[k], per[k]))
        out.append(fitted)
    return out
