"""The moving-block bootstrap the probabilities are drawn from (:mod:`tactrec.probability`)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["bootstrap_probabilities", "lag_one", "REPLICATES", "SEED"]

#: bootstrap replicates, and the seed they are drawn from
REPLICATES, SEED = 2000, 20_261_123


def lag_one(res: Sequence[np.ndarray]) -> float:
    """Pooled lag-one autocorrelation of the residual sequences ``res`` (each along one curve)."""
    num = den = 0.0
    for r in res:
        r = np.asarray(r, dtype=np.float64)
        if len(r) < 3:
            continue
        r = r - r.mean()
        num += float(np.sum(r[1:] * r[:-1]))
        den += float(np.sum(r * r))
    return num / den if den > 0 else 0.0


def _draws(curve_sizes: Sequence[int], block: int, replicates: int, rng) -> np.ndarray:
    """Indices of the points drawn in each replicate ``(B, m)``: blocks of ``block`` consecutive
    points within one curve, starts uniform over the valid ones, until ``m`` points."""
    sizes = np.asarray(curve_sizes, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    starts = np.concatenate([o + np.arange(max(n - block + 1, 1)) for o, n in zip(offsets, sizes)])
    m = int(sizes.sum())
    blocks = -(-m // block)
    first = starts[rng.integers(len(starts), size=(replicates, blocks))]            # (B, blocks)
    return (first[:, :, None] + np.arange(block)[None, None, :]).reshape(replicates, -1)[:, :m]


def bootstrap_probabilities(distances: np.ndarray, curve_sizes: Sequence[int], *, block: int = 1,
                            replicates: int = REPLICATES, rng=SEED) -> np.ndarray:
    """Each row's share of the replicates in which its mean over its resampled points is least.

    ``distances (k, m)``: each model's distances to the ``m`` points, each row resampled on its
    own draws; returns ``(k,)``, summing to 1 (ties shared; empty for no model)."""
    d = np.asarray(distances, dtype=np.float64)
    k = len(d)
    if k == 0:
        return np.zeros(0)
    if k == 1:
        return np.ones(1)
    rng = np.random.default_rng(rng)
    means = np.stack([d[i][_draws(curve_sizes, int(block), int(replicates), rng)].mean(axis=1) for i in range(k)],
                     axis=1)                                                         # (B, k)
    least = means.min(axis=1, keepdims=True)
    tied = means <= least * (1.0 + 1e-12) + 1e-300
    share = tied / tied.sum(axis=1, keepdims=True)
    return share.mean(axis=0)
