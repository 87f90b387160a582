"""How sure a recognition is: each accepted model's probability, from the residuals.

The registration error ranks the models (eq. 9); this module turns the
registered poses into the probability that the data came from each model.

The rule.  A model's registration error (the mean distance of the data points
to it, eq. 8) is a statistic of the data: another touch of the same place,
under another draw of the sensor's noise, would move it.  The probability of
model ``M`` is the probability that it fits best under that variation,
estimated by resampling the data points (a moving-block bootstrap): in each
of ``B`` replicates every accepted model's mean distance is taken over the
data points drawn with replacement, and ``M``'s probability is the share of
replicates in which it has the least (ties shared).

* Models whose fits differ by less than the data's own scatter share the
  probability; a model clear of the others in almost every replicate takes
  almost all of it.  So a touch that fits several models about as well says
  so.
* Each model is resampled on its own draw of the points.  Its error is the
  best over the poses its search tried, a pose chosen for this data: two
  models' errors do not share the noise point by point as two fixed poses
  would, and comparing them point by point (one draw for all) makes the
  best fit's lead look surer than it is, most where the search found another
  model's pose that fits the noise better than the true one.
* Neighbouring residuals along a curve are not independent evidence when a
  fit is off smoothly.  Points are drawn in blocks of ``l`` consecutive points
  of one curve, ``l = (1 + rho) / (1 - rho)`` from the lag-one
  autocorrelation ``rho`` of the best model's signed residuals (1 for white
  residuals, at most the shortest curve), which keeps that dependence in
  every replicate.

Nothing comes from a simulation setting: the scatter is the touch's own.
Models the search rejected or deferred have no probability; the accepted
models' probabilities sum to one.  The replicates are drawn from a fixed seed
and averaged without BLAS, so the same touch gives the same probabilities on
every machine.  ``tactrec bench calibration`` measures how well the
confidence matches the share of right answers.  ``confidence`` is the best model's probability; a result is
``ambiguous`` when it is below :data:`AMBIGUOUS`.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

__all__ = ["Evidence", "residuals", "evidence", "bootstrap_probabilities", "noise_fit", "fit_limit",
           "fit_standard_error", "AMBIGUOUS", "REPLICATES"]

#: a result is ambiguous when its confidence (the best model's probability) is below this
AMBIGUOUS = 0.95
#: bootstrap replicates, and the seed they are drawn from
REPLICATES, SEED = 2000, 20_261_123


def noise_fit(sigma: float) -> float:
    """The mean distance of a perfect fit under Gaussian noise of ``sigma`` per coordinate:
    the half-normal's mean, ``sigma sqrt(2 / pi)``."""
    return float(sigma) * np.sqrt(2.0 / np.pi)


def fit_limit(touch, floor: float) -> float:
    """The largest mean distance (data units) still a fit of ``touch`` (a :class:`~tactrec.features.Touch`):
    a perfect fit's under its noise (:func:`noise_fit`), or ``floor`` x its radius on noise-free
    data, whichever is larger."""
    return max(noise_fit(touch.noise), floor * touch.radius)


def fit_standard_error(fit: float, points: int) -> float:
    """How far another draw of the noise moves a fit of mean distance ``fit`` over ``points`` points:
    the half-normal's spread is ``sqrt(pi / 2 - 1)`` times its mean, so ``fit sqrt(pi / 2 - 1) / sqrt(points)``."""
    return float(fit) * np.sqrt(np.pi / 2.0 - 1.0) / np.sqrt(points)


def residuals(model, rotation: np.ndarray, translation: np.ndarray, points: np.ndarray,
              scale: float = 1.0) -> np.ndarray:
    """Signed distances ``(m,)`` of data ``points (m, 3)`` (data units) to ``model`` under the pose
    ``model = scale * rotation @ data + translation``, in data units (positive outside)."""
    moved = scale * (np.asarray(points, dtype=np.float64) @ np.asarray(rotation).T) + np.asarray(translation)
    return np.asarray(model.planes(moved)[0], dtype=np.float64) / scale


@dataclasses.dataclass(frozen=True)
class Evidence:
    """What the probabilities are computed from, per touch.

    Attributes
    ----------
    models : tuple of str
        The accepted models, best first.
    distances : (k, m) float
        Each data point's distance to each model under its registered pose, data units.
    curve_sizes : tuple of int
        Points per curve (the columns of ``distances`` are the curves in order).
    rho : float
        Lag-one autocorrelation of the best model's signed residuals along the curves.
    noise : float
        The data's noise sigma per coordinate (third differences), data units; reported only.
    """

    models: tuple
    distances: np.ndarray
    curve_sizes: tuple
    rho: float
    noise: float = 0.0

    @property
    def block(self) -> int:
        """Points per bootstrap block, ``(1 + rho) / (1 - rho)`` rounded, between 1 and the shortest curve."""
        rho = float(np.clip(self.rho, 0.0, 0.999))
        return int(np.clip(round((1.0 + rho) / (1.0 - rho)), 1, max(1, min(self.curve_sizes, default=1))))

    def probabilities(self, *, replicates: int = REPLICATES, rng=SEED) -> np.ndarray:
        """Each model's share of the bootstrap replicates it fits best in, ``(k,)`` (sum 1)."""
        return bootstrap_probabilities(self.distances, self.curve_sizes, block=self.block, replicates=replicates,
                                       rng=rng)

    def to_json(self) -> dict:
        return {"models": list(self.models), "distances": np.round(self.distances, 7).tolist(),
                "curve_sizes": list(self.curve_sizes), "rho": self.rho, "noise": self.noise}

    @classmethod
    def from_json(cls, d: dict) -> "Evidence":
        return cls(tuple(d["models"]), np.asarray(d["distances"], dtype=np.float64).reshape(len(d["models"]), -1),
                   tuple(int(n) for n in d["curve_sizes"]), float(d["rho"]), float(d.get("noise", 0.0)))


def _lag_one(res: Sequence[np.ndarray]) -> float:
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


def evidence(models: Sequence[str], signed: Sequence[np.ndarray], curve_sizes: Sequence[int],
             noise: float = 0.0) -> Evidence:
    """The :class:`Evidence` from each accepted model's signed residuals ``(m,)`` (best model first;
    curves in order, ``curve_sizes`` points each)."""
    sizes = tuple(int(n) for n in curve_sizes)
    m = sum(sizes)
    rows = [np.abs(np.asarray(r, dtype=np.float64)) for r in signed]
    rho = _lag_one(np.split(np.asarray(signed[0], dtype=np.float64), np.cumsum(sizes)[:-1])) if rows else 0.0
    return Evidence(tuple(models), np.array(rows).reshape(len(rows), m), sizes, float(rho), float(noise))


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
