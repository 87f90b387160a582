"""A session's pose families: the poses along the motions its touches leave free.

Touches on a cylinder leave a slide along its axis and a turn about it free;
on a flat patch, two slides and a turn.  The poses along those motions fit
the touches as well as the best, and :func:`tactrec.proposal.propose` weighs
them as hypotheses of their own (:meth:`tactrec.session.Session.family`).
"""

from __future__ import annotations

import numpy as np

from ..linalg import compose, dot3, eigh, gram, norm3, rotate, times
from ..registration.step import jacobian
from .fit import joint_model, per_touch, refine

__all__ = ["free_poses", "distinct", "FAMILY", "APART", "FREE", "FAMILY_ITERATIONS"]

#: poses kept per model (the best and others the touches fit as well), and how far apart their contacts must be
#: (a fraction of the touches' reach)
FAMILY, APART = 5, 0.5
#: a motion is free when the fit's curvature along it is below this fraction of the largest; Gauss-Newton
#: steps of a pose moved along it
FREE, FAMILY_ITERATIONS = 1e-3, 6


def free_poses(touches, model, best, use: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``best``'s pose, then poses along the motions the touches leave free (``touches``, a
    :class:`~.touches.Touches`) (the directions
    of least curvature of the fit's point-to-plane normal matrix, below :data:`FREE` x its
    largest): each moved by a quarter and a half of the model's size both ways, refined,
    and kept if every touch used is still consistent with it (see :func:`distinct`)."""
    from ..registration.result import rotations_from_vectors

    moved = times(x, best.rotation.T) + best.translation
    n = model.planes(moved)[1]
    values, vectors = eigh(gram(jacobian(moved, n)[None])[0])                         # J^T J (6, 6)
    centre = moved.mean(axis=0)
    R, t = [], []
    for k in np.nonzero(values < FREE * values[-1])[0]:
        w, u = vectors[:3, k], vectors[3:, k]
        step = norm3(np.cross(w, centre) + u)                   # the data centre's speed
        if step <= 0:
            continue
        # the screw the twist (w, u) generates: a turn about the axis through q, a slide along it
        turning = norm3(w) * model.size > 1e-6 * norm3(u)
        q = np.cross(w, u) / dot3(w, w) if turning else np.zeros(3)
        slide = dot3(w, u) / dot3(w, w) * w if turning else u
        for f in (-0.5, -0.25, 0.25, 0.5):
            a = f * model.size / step
            dR = rotations_from_vectors((a * w)[None])[0] if turning else np.eye(3)
            R.append(compose(dR, best.rotation))
            t.append(rotate(dR, best.translation - q) + q + a * slide)
    if not R:
        return distinct(touches, best, np.empty((0, 3, 3)), np.empty((0, 3)))
    points, tips = [f.points for f in touches.features], touches.tips
    R, t = refine(joint_model(model, points, tips, best.scale, use), np.array(R), np.array(t), x, FAMILY_ITERATIONS)
    per = per_touch(model, R, t, points, best.scale, tips)
    fits = touches.consistent(best.model, per)[:, use].all(axis=1)
    return distinct(touches, best, R[fits], t[fits])


def distinct(touches, best, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``best``'s pose and up to :data:`FAMILY` - 1 of the poses ``R, t`` that put the touches'
    contacts more than :data:`APART` x the touches' reach from where every pose kept puts them."""
    contacts = np.array([f.geometry.contact for f in touches.features]) * best.scale
    reach = max(f.reach for f in touches.features) * best.scale
    kept = [np.concatenate([best.rotation, best.translation[:, None]], axis=1)]
    where = [times(contacts, best.rotation.T) + best.translation]
    for Rk, tk in zip(R, t):
        if len(kept) >= FAMILY:
            break
        x = times(contacts, Rk.T) + tk
        if all(np.max(np.linalg.norm(x - w, axis=1)) > APART * reach for w in where):
            kept.append(np.concatenate([Rk, tk[:, None]], axis=1))
            where.append(x)
    return np.array(kept)
