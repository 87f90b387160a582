"""How well a predicted touch would tell a session's hypotheses apart, in the probabilities' currency
(:mod:`tactrec.proposal`, Gain)."""

from __future__ import annotations

import numpy as np
from scipy.special import erf

from ..linalg import transform
from ..probability import open_world
from ..registration.step import jacobian, normal_matrix, prior_steps

__all__ = ["entropy", "model_points", "pose_jacobian", "information", "refit", "excess", "separation", "expected_gain"]


def entropy(p: np.ndarray) -> float:
    p = p[p > 1e-300]
    return float(-np.sum(p * np.log2(p)))


def model_points(pose: np.ndarray, scale: float, x_world: np.ndarray) -> np.ndarray:
    """World points ``x_world (..., 3)`` in the model frame under ``pose (3, 4)`` and ``scale``."""
    x = np.asarray(x_world, dtype=np.float64)
    return transform(pose[None, :, :3], pose[None, :, 3], scale * x.reshape(-1, 3))[0].reshape(x.shape)


def pose_jacobian(model, moved: np.ndarray):
    """Signed distances ``(m,)`` of model-frame points ``moved (m, 3)`` and their pose Jacobian
    ``(m, 6)``: the change of each distance under a small turn ``w`` about the model's origin and
    shift ``u`` of the model frame, ``(m x n) . w + n . u`` (:func:`tactrec.registration.step.jacobian`)."""
    d, n = model.planes(moved)
    return d, jacobian(moved, n)


def information(model, pose: np.ndarray, scale: float, x_world: np.ndarray) -> np.ndarray:
    """``J0^T J0 (6, 6)`` of world points ``x_world (m, 3)`` under ``pose (3, 4)``, model units
    (:func:`tactrec.registration.step.normal_matrix`)."""
    moved = model_points(pose, scale, x_world)
    return normal_matrix(moved, np.ascontiguousarray(model.planes(moved)[1], dtype=np.float64))


def refit(model, pose: np.ndarray, scale: float, H0: np.ndarray, x_world: np.ndarray, kept: np.ndarray):
    """Each of ``n`` predicted touches ``x_world (n, k, 3)`` against ``model`` once the pose
    ``(3, 4)`` is refitted to that touch's predicted points (``kept (n, k)``, bool) and the earlier
    touches (information ``H0 (6, 6)``) together, by the one damped point-to-plane step
    (:func:`tactrec.registration.step.prior_steps`; module text): the touch's signed distances
    after the step ``(n, k)`` (0 where not predicted) and the sum of squares the step adds to the
    earlier touches' ``(n,)``, world units."""
    moved = model_points(pose, scale, x_world)
    r, normals = model.planes(moved.reshape(-1, 3))
    shape = moved.shape
    c = np.ascontiguousarray
    _, after, added = prior_steps(c(H0, dtype=np.float64), c(moved), c(normals, dtype=np.float64).reshape(shape),
                                  c(r, dtype=np.float64).reshape(shape[:2]), c(kept, dtype=np.float64))
    return after / scale, added / scale ** 2


def excess(offset: np.ndarray, sigma: float) -> np.ndarray:
    """What a point ``offset`` from the surface adds to a fit's mean distance under Gaussian noise of
    ``sigma``: the folded normal's mean less the half-normal's (quadratic below ``sigma``, then
    linear)."""
    a = np.abs(offset)
    with np.errstate(under="ignore"):
        folded = sigma * np.sqrt(2.0 / np.pi) * np.exp(-0.5 * (a / sigma) ** 2) + a * erf(a / (sigma * np.sqrt(2.0)))
    return folded - sigma * np.sqrt(2.0 / np.pi)


def separation(model, h, H0: np.ndarray, predicted: np.ndarray, sigma: float, earlier: int,
                kept: np.ndarray | None = None) -> np.ndarray:
    """How many standard errors ``(n,)`` the session's mean distance on ``model``, refitted from
    pose ``h`` (module text), would exceed the truth's if each of the ``predicted (n, k, 3)``
    touches were added (their predicted points ``kept (n, k)``, bool; all by default): the points'
    excess distances (:func:`excess`; the earlier touches' ``earlier`` points share the sum of
    squares the refit adds to them) over the spread of a difference of two fits' mean distances
    over all the points."""
    kept = np.ones(predicted.shape[:2], dtype=bool) if kept is None else np.asarray(kept, dtype=bool)
    pose = np.concatenate([h.rotation, h.translation[:, None]], axis=1)
    offsets, added = refit(model, pose, h.scale, H0, predicted, kept)
    total = kept.sum(axis=1) + earlier
    extra = (excess(offsets, sigma) * kept).sum(axis=1) + earlier * excess(np.sqrt(added / earlier), sigma)
    spread = sigma * np.sqrt(1.0 - 2.0 / np.pi)                      # a half-normal distance's
    return extra / (spread * np.sqrt(2.0 * total))


def expected_gain(weights: np.ndarray, unknown: float, z: np.ndarray, hits: np.ndarray, truth: np.ndarray,
                  takes: np.ndarray) -> float:
    """The expected information gain (bits) of a touch about the models and ``unknown``.

    ``weights (k,)`` are the models' probabilities and ``unknown`` unknown's (together 1); for each
    of the ``p`` truth poses, ``z (p, k)`` is by how many standard errors each model's refitted
    pose would fit the touch worse than the truth's (:func:`separation`), ``hits (p,)`` whether it
    meets the line, ``truth (p,)`` its probability and ``takes (p,)`` whether it predicts an outcome.
    Under truth pose ``i`` model ``M`` is weighted by ``exp(-z_iM^2 / 2)``, and ``unknown`` by the
    open world's likelihood of a fit against a model's at the test's edge
    (:func:`tactrec.probability.open_world`) where the truth meets the line (a touch the true pose
    fits), by 1 where it meets nothing (no fit to weigh).  The gain is the divergence of the
    probabilities after the touch from those now (Kullback-Leibler, bits), expected over the
    truths: never negative, 0 for a line that changes nothing.  If the object is none of them
    (``unknown``), what the line shows cannot be predicted: that share gains nothing."""
    edge = open_world(np.ones(1), np.zeros(1), prior=0.5)        # at even odds: the likelihoods' ratio
    fit = edge[1] / edge[0][0]                              # unknown against a model that fits the touch
    before = np.append(weights, unknown)
    with np.errstate(under="ignore"):
        after = weights[None, :] * np.exp(-0.5 * np.minimum(z * z, 1400.0))
    u = np.where(hits, unknown * fit, unknown)
    out = 0.0
    for i in np.nonzero(takes)[0]:
        q = np.append(after[i], u[i])
        q = q / q.sum()
        kept = (q > 1e-300) & (before > 0.0)
        out += truth[i] * float(np.sum(q[kept] * np.log2(q[kept] / before[kept])))
    return out
