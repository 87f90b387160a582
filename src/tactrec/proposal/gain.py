"""How well a predicted touch would tell a session's hypotheses apart, in the probabilities' currency
(:mod:`tactrec.proposal`, Gain)."""

from __future__ import annotations

import numpy as np
from scipy.special import erf

from ..probability import open_world
from ..registration.solver import jacobian

__all__ = ["entropy", "pose_jacobian", "information", "refit", "excess", "separation", "expected_gain"]


def entropy(p: np.ndarray) -> float:
    p = p[p > 1e-300]
    return float(-np.sum(p * np.log2(p)))


def pose_jacobian(model, moved: np.ndarray):
    """Signed distances ``(m,)`` of model-frame points ``moved (m, 3)`` and their pose Jacobian
    ``(m, 6)``: the change of each distance under a small turn ``w`` (per model size) and shift
    ``u`` of the model frame, ``(m x n) . w + n . u``."""
    d, n = model.planes(moved)
    J = jacobian(moved, n)
    J[:, :3] /= model.size
    return d, J


def information(model, pose: np.ndarray, scale: float, x_world: np.ndarray) -> np.ndarray:
    """``J0^T J0 (6, 6)`` of world points ``x_world (m, 3)`` under ``pose (3, 4)``, model units."""
    _, J = pose_jacobian(model, scale * x_world @ pose[:, :3].T + pose[:, 3])
    return np.einsum("mi,mj->ij", J, J)


def refit(model, pose: np.ndarray, scale: float, H0: np.ndarray, x_world: np.ndarray, kept: np.ndarray):
    """Each of ``n`` predicted touches ``x_world (n, k, 3)`` against ``model`` once the pose
    ``(3, 4)`` is refitted to that touch's predicted points (``kept (n, k)``, bool) and the earlier
    touches (information ``H0 (6, 6)``) together, by one Gauss-Newton step (module text): the
    touch's signed distances after the step ``(n, k)`` (0 where not predicted) and the sum of
    squares the step adds to the earlier touches' ``(n,)``, world units."""
    n, k = x_world.shape[:2]
    r, J = pose_jacobian(model, (scale * x_world.reshape(-1, 3) @ pose[:, :3].T + pose[:, 3]))
    r, J = r.reshape(n, k) * kept, J.reshape(n, k, 6) * kept[..., None]
    H = H0[None] + np.einsum("nmi,nmj->nij", J, J)
    b = np.einsum("nmi,nm->ni", J, r)
    ridge = 1e-12 * np.maximum(np.trace(H, axis1=1, axis2=2), 1e-300)
    step = -np.linalg.solve(H + ridge[:, None, None] * np.eye(6), b[..., None])[..., 0]
    after = r + np.einsum("nmi,ni->nm", J, step)
    return after / scale, np.einsum("ni,ij,nj->n", step, H0, step) / scale ** 2


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
