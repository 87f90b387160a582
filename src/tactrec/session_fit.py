"""Step 2 of a session (:mod:`tactrec.session`): one model's candidate poses scored on every touch,
the best refined jointly.  A stage of the recognizer's runner (:class:`tactrec.recognition.Recognizer`),
so the models of a session are fitted in its worker processes, each model's arithmetic the same in
any process."""

from __future__ import annotations

import numpy as np

from .linalg import transform

__all__ = ["refine", "per_touch", "fit_stage", "JOINT_ITERATIONS", "REFINED", "CHEAP_STEPS", "COARSE_POINTS"]

#: Gauss-Newton steps of a joint refinement, and how many candidate poses per model are refined
JOINT_ITERATIONS, REFINED = 15, 2
#: the cheap steps every candidate takes before the cut, on this many points of each curve (as the
#: ``fast`` method's cheap stage: :class:`~tactrec.methods.fast.FastConfig` ``cheap_steps``, ``coarse_points``)
CHEAP_STEPS, COARSE_POINTS = 2, 5


def refine(model, R: np.ndarray, t: np.ndarray, x: np.ndarray, iterations: int):
    """Poses ``R (h, 3, 3), t (h, 3)`` refined on points ``x (m, 3)`` (model units): ``R, t, error (h,)``."""
    if model.kind == "mesh":
        from .registration import mesh_fast

        R, t, error, _ = mesh_fast.refine(model, R, t, x, iterations=iterations)
        return R, t, error
    from .registration import closedform_fast

    return closedform_fast.refine(model, R, t, x, iterations=iterations)


def per_touch(model, R: np.ndarray, t: np.ndarray, points: list, scale: float) -> np.ndarray:
    """Mean distance of each touch's points ``points[i] (m_i, 3)`` (data units) under poses
    ``R (h, 3, 3), t (h, 3)``: ``(h, N)``, data units."""
    out = []
    for x in points:
        d = model.distance(transform(R, t, x * scale)) / scale
        out.append(np.mean(d, axis=1))
    return np.stack(out, axis=1)


def fit_stage(held, indices, points: list, weight: np.ndarray, coarse: list, items: list) -> list:
    """Per model at ``indices``, its candidate poses ``items[k] = (R (h, 3, 3), t (h, 3), scale)``
    scored on every touch (``points[i] (m_i, 3)``: touch ``i``'s points, data units), each also
    after :data:`CHEAP_STEPS` Gauss-Newton steps on ``coarse[i]`` (a few points of each curve of
    touch ``i``, as a search's cheap stage), the better of the two kept; ranked by the mean
    distances summed over the touches weighted by ``weight (N,)`` (points a touch, 0 for a touch
    left out), the best :data:`REFINED` refined on every point of the touches weighted
    (:data:`JOINT_ITERATIONS` steps).  A start's distances say little about where it converges
    (a pose one touch fits and another misses by a millimetre may slide onto both), so every
    candidate takes the cheap steps before the cut.  Returns per model a list of ``(R (3, 3),
    t (3,), per (N,))``, a refined pose or its start when refining did not lower the weighted sum."""
    used = np.concatenate([p for p, w in zip(points, weight) if w > 0])
    cheap = np.concatenate([p for p, w in zip(coarse, weight) if w > 0])
    out = []
    for index, (R, t, scale) in zip(indices, items):
        model = held.entries[index].model
        per = per_touch(model, R, t, points, scale)                                      # (h, N)
        total = (per * weight).sum(axis=1)                  # element-wise: no BLAS kernel in the ranking
        Rc, tc, _ = refine(model, R, t, cheap * scale, CHEAP_STEPS)
        per_c = per_touch(model, Rc, tc, points, scale)
        total_c = (per_c * weight).sum(axis=1)
        moved = total_c < total                                                 # the better of start and steps
        R, t = np.where(moved[:, None, None], Rc, R), np.where(moved[:, None], tc, t)
        per, total = np.where(moved[:, None], per_c, per), np.where(moved, total_c, total)
        best = np.argsort(total, kind="stable")[:REFINED]
        Rb, tb, _ = refine(model, R[best], t[best], used * scale, JOINT_ITERATIONS)   # one batch: each pose its own
        per_b = per_touch(model, Rb, tb, points, scale)
        fitted = []
        for j, k in enumerate(best):
            if (per_b[j] * weight).sum() <= total[k]:
                fitted.append((Rb[j], tb[j], per_b[j]))
            else:                                                               # keep the start if not better
                fitted.append((R[k], t[k], per[k]))
        out.append(fitted)
    return out
