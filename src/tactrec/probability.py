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

The open world.  Those shares compare the models with each other only.  A
robot also touches objects it was never taught, so the probabilities weigh
``unknown`` too (:func:`open_world`): each model's share is weighted by how
well its pose fits the data under their own noise, the fit test as a
likelihood.  A touch's mean distance to the true model's pose is the noise's
(:func:`fit_limit`, on noise-free data ``floor`` x the touch's radius); its
excess beyond that, in standard errors of the fit and of the noise estimate
together (:func:`fit_spread`), is Gaussian with unit variance when the model
is the true one.  ``unknown`` explains any touch as well as a model at the
test's edge (:data:`CONSISTENT_SE` standard errors out), and its prior
(:data:`UNKNOWN_PRIOR`, settable) weighs it against the models together.  The
search may miss the true pose (:data:`SEARCH_MISS`): a model beyond the test
keeps that much of the edge's likelihood, so that a touch whose search did
not settle is never sure either way.  In a session every kept touch is
evidence, each counted at the excess of the touch the model's joint pose
fits worst: the pose must fit each of them, and each touch it fits makes
unknown less likely.  A line the sensor followed without meeting anything
must not cut into the surface (:mod:`tactrec.missed`).

The resolution.  A sensor, a scan's facets and the search's own steps all
resolve distances down to some size, and below it two fits are equal: a
point's distance below :func:`resolution` (``floor`` x the touch's radius,
what a fit of noise-free data may leave) is read as that, in the shares.
Without it two fits of 1e-15 and 3e-15 mm (a CAD part's flat face and
another's) read as the strongest evidence.  A fit whose points lie beyond
the resolution still loses to one within it.

An unsettled search.  A search that ended on its budget, its best beyond a plausible fit
(:func:`plausible_fit`), has missed the true pose somewhere: its errors only bound each model's fit.
Two bounds order nothing (a noise-free touch of a ring whose twin shares the touched surface stopped
at 0.016 mm on the ring and 0.013 mm on the twin, both fitting at 0, and the twin was called sure).  So
the models within the search's ``ratio`` of the best, which its next round would have searched, are
*tied* (:attr:`Evidence.tied`): read at the best's distances, in the shares and the fit test, sharing
evenly.  The answer is still the lowest error; how sure it is falls with each model tied to it.

Nothing comes from a simulation setting: the scatter is the touch's own.  Points off their curve's trace
(:mod:`tactrec.outliers`) are no evidence for or against any model.  Models the search rejected or deferred
have no probability; the accepted models' probabilities and ``unknown``'s sum to one.  The replicates are drawn
from a fixed seed and averaged without BLAS, so the same touch gives the same probabilities on every
machine.  ``tactrec bench calibration`` and ``tactrec bench open-world`` measure how well the confidence
matches the share of right answers.  ``confidence`` is the best model's probability; a result is ``ambiguous``
when it is below :data:`AMBIGUOUS`.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from .bootstrap import REPLICATES, SEED, bootstrap_probabilities, lag_one
from .linalg import times

__all__ = ["Evidence", "residuals", "evidence", "bootstrap_probabilities", "noise_fit", "fit_limit", "resolution",
           "fit_standard_error", "plausible_fit", "fit_spread", "open_world", "AMBIGUOUS", "REPLICATES", "UNKNOWN_PRIOR",
           "CONSISTENT_SE", "NOISE_VARIANCE", "SEARCH_MISS", "FLOOR", "most_probable"]

#: on noise-free data a fit is within this fraction of the touch's radius, for a method without a ``floor`` of
#: its own (:func:`resolution`)
FLOOR = 1e-3
#: a result is ambiguous when its confidence (the best model's probability) is below this
AMBIGUOUS = 0.95
#: the prior probability that a touch (or session) comes from none of the database's models
UNKNOWN_PRIOR = 0.5
#: the probability that the search leaves the touched model's true pose unfound, its best pose beyond the fit
#: test: the share of known P3 touches that do so in ``tactrec bench open-world`` (5 of 50 on the ten
#: ``paper-fig11`` scans; its ``own model beyond the test`` column)
SEARCH_MISS = 0.1
#: the fit test's allowance: a mean distance fits when within this many of its standard errors of a fit
CONSISTENT_SE = 3.0
#: the relative variance of the noise estimate (:func:`tactrec.estimation.noise_level`, the median over
#: three curves) times the points it is taken over, for white Gaussian noise: 1.14, 1.10, 1.04 and 1.01
#: on 21, 41, 81 and 161 points a curve (4,000 draws each; ``tests/test_open_world.py`` checks it)
NOISE_VARIANCE = 1.1


def most_probable(names: Sequence[str], probabilities: dict[str, float]) -> str | None:
    """The answer of a ranking, for single touches and sessions alike: of ``names`` (the models with a
    pose, ranked by error, best first) the most probable, the first of equals; the first where none
    has a probability (None where there is none)."""
    if not names:
        return None
    if not probabilities:
        return names[0]
    return max(names, key=lambda name: probabilities.get(name, 0.0))


def resolution(touch, floor: float) -> float:
    """The least distance of a point of ``touch`` to a model read as such (data units): ``floor`` x its
    radius, what a fit of noise-free data may leave (:func:`fit_limit`); for single contacts, whose noise is
    stated, at least a perfect fit's under it (:func:`noise_fit`): closer fits of a few contacts order nothing."""
    least = float(floor) * float(touch.radius)
    if getattr(getattr(touch, "data", None), "contacts", None) is not None:
        least = max(least, noise_fit(touch.noise))
    return least


def noise_fit(sigma: float) -> float:
    """The mean distance of a perfect fit under Gaussian noise of ``sigma``: ``sigma sqrt(2 / pi)``."""
    return float(sigma) * np.sqrt(2.0 / np.pi)


def fit_limit(touch, floor: float) -> float:
    """The largest mean distance (data units) still a fit of ``touch`` (a :class:`~tactrec.features.Touch`):
    a perfect fit's under its noise (:func:`noise_fit`), or ``floor`` x its radius on noise-free
    data, whichever is larger."""
    return max(noise_fit(touch.noise), resolution(touch, floor))


def fit_standard_error(fit: float, points: int) -> float:
    """How far another draw of the noise moves a fit of mean distance ``fit`` over ``points`` points:
    the half-normal's spread is ``sqrt(pi / 2 - 1)`` times its mean, so ``fit sqrt(pi / 2 - 1) / sqrt(points)``."""
    return float(fit) * np.sqrt(np.pi / 2.0 - 1.0) / np.sqrt(points)


def plausible_fit(limit: float, noise: float, points: int, within: float) -> float:
    """The largest best error (data units) still a fit of ``points`` points of noise ``noise`` and fit limit
    ``limit``: ``within`` standard errors of a fit above the limit, or the limit itself where the noise's
    spread stays below it (noise-free data, whose true pose fits far within it)."""
    fit = noise_fit(noise)
    if fit + within * fit_standard_error(fit, points) <= limit:
        return float(limit)
    return float(limit + within * fit_standard_error(limit, points))


def fit_spread(limit: float, points: int) -> float:
    """The standard error of a fit's mean distance, measured against ``limit`` (:func:`fit_limit`)
    over ``points`` points, when the model is the true one: the mean distance's own spread
    (:func:`fit_standard_error`) and that of the noise estimate the limit comes from
    (:data:`NOISE_VARIANCE`), ``limit sqrt((pi / 2 - 1 + NOISE_VARIANCE) / points)``."""
    return float(limit) * np.sqrt((np.pi / 2.0 - 1.0 + NOISE_VARIANCE) / max(int(points), 1))


def open_world(shares: np.ndarray, excess: np.ndarray, prior: float = UNKNOWN_PRIOR,
               miss: float = SEARCH_MISS, touches: int = 1, *, ratio: float | None = None,
               lines: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Each model's probability and that of ``unknown`` (none of them), summing to 1.

    ``shares (k,)``: each model's share of the bootstrap replicates it fits best in (sum 1);
    ``excess (k,)``: by how many standard errors (:func:`fit_spread`) its pose's mean distance
    exceeds the fit limit on the touch it fits worst, of ``touches``.

    The fit test as a likelihood, per touch: the data fit a model's pose with likelihood
    ``exp(-max(z, 0)^2 / 2)``, 1 within the noise, and ``unknown`` explains any touch as well as a
    model at the test's edge, ``z = CONSISTENT_SE``.  Every touch is counted at the worst touch's
    excess, so that one touch the pose does not fit is not outweighed by the others: relative to
    unknown, the pose's touches weigh ``F = exp(-touches (max(excess, 0)^2 - CONSISTENT_SE^2) / 2)``.
    The search may have missed the touched model's true pose (with probability ``miss``), leaving
    poses that fit no better than an unrelated object's: then its touches weigh as unknown's.  With
    the prior ``prior`` for unknown, ``p(M) ~ (1 - prior) share(M) ((1 - miss) F + miss)`` and
    ``p(unknown) ~ prior``.

    So a model whose pose fails the test on some touch never takes more than ``1 - prior`` of the
    probability, and far beyond the edge at most ``(1 - prior) miss / ((1 - prior) miss + prior)``;
    one within the noise on every touch leaves unknown about
    ``prior exp(-touches CONSISTENT_SE^2 / 2) / ((1 - prior) (1 - miss))``, less with every touch.

    With the database's null model of chance fits (:mod:`tactrec.chance`), ``ratio`` is its
    likelihood ratio, known against unknown, of the touches' best fits: it replaces the fit test's
    fixed weight for the search over every pose of every model (the chance that some pose of some
    model fits by chance, and that the search missed the truth's, are both in it).  A session's
    further touches test the pose that search found, a prediction with nothing left to choose: each
    counts as before, at the worst touch's excess, and ``lines (k,)`` (the largest excess of a line
    that met nothing, or None) counts against its pose once:
    ``p(M) ~ (1 - prior) share(M) ratio ((1 - miss) G + miss)``,
    ``G = exp(-(touches - 1) (max(excess, 0)^2 - CONSISTENT_SE^2) / 2 - max(lines, 0)^2 / 2)``."""
    if not 0.0 <= prior < 1.0:
        raise ValueError(f"the prior of unknown must lie in [0, 1), not {prior!r}")
    if not 0.0 <= miss < 1.0:
        raise ValueError(f"the search's miss rate must lie in [0, 1), not {miss!r}")
    shares = np.asarray(shares, dtype=np.float64)
    if len(shares) == 0:
        return np.zeros(0), 1.0
    z = np.maximum(np.asarray(excess, dtype=np.float64), 0.0)
    n = max(int(touches), 1)
    with np.errstate(under="ignore", over="ignore"):
        if ratio is None:
            weight = np.exp(np.minimum(-0.5 * n * (z * z - CONSISTENT_SE ** 2), 600.0))
            known = (1.0 - prior) * shares * ((1.0 - miss) * weight + miss)
        else:
            cut = 0.0 if lines is None else np.maximum(np.asarray(lines, dtype=np.float64), 0.0) ** 2
            weight = np.exp(np.minimum(-0.5 * (n - 1) * (z * z - CONSISTENT_SE ** 2) - 0.5 * cut, 600.0))
            known = (1.0 - prior) * shares * float(ratio) * ((1.0 - miss) * weight + miss)
    unknown = float(prior)
    total = float(known.sum()) + unknown
    if total <= 0.0:                                                  # a closed world and no pose near a fit
        return shares, 0.0
    return known / total, unknown / total


def residuals(model, rotation: np.ndarray, translation: np.ndarray, points: np.ndarray,
              scale: float = 1.0) -> np.ndarray:
    """Signed distances ``(m,)`` of data ``points (m, 3)`` (data units) to ``model`` under the pose
    ``model = scale * rotation @ data + translation``, in data units (positive outside)."""
    moved = scale * times(points, np.asarray(rotation).T) + np.asarray(translation)
    return np.asarray(model.planes(moved)[0], dtype=np.float64) / scale


@dataclasses.dataclass(frozen=True)
class Evidence:
    """What the probabilities are computed from.

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
    limits : tuple of float
        Per touch, the largest mean distance still a fit (:func:`fit_limit`), data units; empty for
        a closed world (no ``unknown``: the probabilities compare the models only).
    touches : tuple of int
        Curves per touch, in order (empty: all the curves are one touch).
    misses : (k, q) float or None
        Per model, the excess of each of ``q`` lines the sensor followed without meeting anything
        (:mod:`tactrec.missed`: how far the line cuts into its surface under its pose, in
        the fit test's units; 0 where it stays outside).
    resolution : float
        The least distance a fit is read at (data units, :func:`resolution`): the shares compare
        the distances with those below it read as it.
    radii : tuple of float
        Per touch, its radius (data units): with ``limits``, how much it resolves
        (:mod:`tactrec.chance`); empty where not recorded.
    tied : int
        How many of the models, best first, are read at the best's distances (module text, an
        unsettled search): 1 where the search settled.
    kind : str
        The touches' kind (``curves``, ``patch``, ``contacts``; ``mixed`` where a session's differ): the
        null model of chance fits weighs it against its calibration touches of that kind.
    """

    models: tuple
    distances: np.ndarray
    curve_sizes: tuple
    rho: float
    noise: float = 0.0
    limits: tuple = ()
    touches: tuple = ()
    misses: np.ndarray | None = None
    resolution: float = 0.0
    radii: tuple = ()
    tied: int = 1
    kind: str = "curves"

    @property
    def block(self) -> int:
        """Points per bootstrap block, ``(1 + rho) / (1 - rho)`` rounded, between 1 and the shortest curve."""
        rho = float(np.clip(self.rho, 0.0, 0.999))
        return int(np.clip(round((1.0 + rho) / (1.0 - rho)), 1, max(1, min(self.curve_sizes, default=1))))

    def shares(self, *, replicates: int = REPLICATES, rng=SEED) -> np.ndarray:
        """Each model's share of the bootstrap replicates it fits best in, ``(k,)`` (sum 1)."""
        read = np.maximum(self.read, self.resolution)          # nothing is read closer than the resolution
        shares = bootstrap_probabilities(read, self.curve_sizes, block=self.block, replicates=replicates, rng=rng)
        if self.tied > 1:                                       # tied models share evenly, to the last digit
            shares[:self.tied] = shares[:self.tied].sum() / self.tied
        return shares

    @property
    def read(self) -> np.ndarray:
        """The distances as the probabilities read them ``(k, m)``: the :attr:`tied` models' at the best's."""
        if self.tied <= 1 or len(self.distances) < 2:
            return self.distances
        read = self.distances.copy()
        read[1:self.tied] = read[0]
        return read

    def touch_points(self) -> np.ndarray:
        """Points per touch ``(T,)``."""
        sizes = np.asarray(self.curve_sizes, dtype=np.int64)
        per = self.touches or (len(sizes),)
        return np.add.reduceat(sizes, np.concatenate([[0], np.cumsum(per)[:-1]])) if len(sizes) else np.zeros(0, int)

    def excess(self, *, lines: bool = True) -> np.ndarray:
        """Per model ``(k,)``: by how many standard errors (:func:`fit_spread`) its pose's mean distance
        exceeds the fit limit on the touch it fits worst (negative within the noise), or (``lines``)
        a missed line's excess where that is larger."""
        k = len(self.models)
        if not self.limits or k == 0:
            return np.full(k, -np.inf)
        points = self.touch_points()
        bounds = np.concatenate([[0], np.cumsum(points)])
        z, read = np.empty((k, len(points))), self.read
        for j, (limit, m) in enumerate(zip(self.limits, points)):
            mean = read[:, bounds[j]:bounds[j + 1]].sum(axis=1) / max(int(m), 1)   # no BLAS
            spread = fit_spread(limit, m)
            z[:, j] = (mean - limit) / spread if spread > 0 else np.where(mean > limit, np.inf, -np.inf)
        worst = z.max(axis=1)
        cut = self.line_excess() if lines else None
        return worst if cut is None else np.maximum(worst, cut)

    def outcomes(self, *, prior: float = UNKNOWN_PRIOR, miss: float = SEARCH_MISS, replicates: int = REPLICATES,
                 rng=SEED, chance=None) -> tuple[np.ndarray, float]:
        """Each model's probability ``(k,)`` and that of ``unknown`` (:func:`open_world`; sum 1).  Without
        ``limits`` (a closed world) unknown is 0 and the models' probabilities are their shares.
        ``chance``: the database's null model of chance fits (:class:`tactrec.chance.NullModel`), whose
        likelihood ratio of this evidence (:meth:`~tactrec.chance.NullModel.ratio_of`) then weighs the
        touches against unknown (:func:`open_world`'s ``ratio``)."""
        shares = self.shares(replicates=replicates, rng=rng)
        if not self.limits:
            return shares, 0.0
        ratio = None
        if chance is not None and len(self.radii) == len(self.limits) and len(self.models):
            ratio = chance.ratio_of(self)
        if ratio is None:
            return open_world(shares, self.excess(), prior, miss, max(len(self.limits), 1))
        return open_world(shares, self.excess(lines=False), prior, miss, max(len(self.limits), 1), ratio=ratio,
                          lines=self.line_excess())

    def line_excess(self) -> np.ndarray | None:
        """Per model ``(k,)``: the largest excess of a line that met nothing (None without such lines)."""
        if self.misses is None or not np.size(self.misses):
            return None
        return np.asarray(self.misses, dtype=np.float64).max(axis=1)

    def named_outcomes(self, *, prior: float = UNKNOWN_PRIOR, chance=None) -> tuple[dict[str, float], float]:
        """:meth:`outcomes` with each model's probability by name: ``({model: p}, unknown)``."""
        p, unknown = self.outcomes(prior=prior, chance=chance)
        return dict(zip(self.models, p.tolist())), unknown

    def probabilities(self, *, prior: float = UNKNOWN_PRIOR, replicates: int = REPLICATES,
                      rng=SEED) -> np.ndarray:
        """Each model's probability ``(k,)`` (:meth:`outcomes`)."""
        return self.outcomes(prior=prior, replicates=replicates, rng=rng)[0]

    def to_json(self) -> dict:
        out = {"models": list(self.models), "distances": np.round(self.distances, 7).tolist(),
               "curve_sizes": list(self.curve_sizes), "rho": self.rho, "noise": self.noise,
               "limits": [float(x) for x in self.limits], "touches": list(self.touches),
               "resolution": float(self.resolution), "radii": [float(x) for x in self.radii], "tied": int(self.tied),
               "kind": self.kind}
        if self.misses is not None:
            out["misses"] = np.asarray(self.misses, dtype=np.float64).tolist()
        return out

    @classmethod
    def from_json(cls, d: dict) -> "Evidence":
        k = len(d["models"])
        m = sum(int(n) for n in d["curve_sizes"])
        misses = d.get("misses")
        if misses is not None:
            misses = np.asarray(misses, dtype=np.float64).reshape(k, len(misses[0]) if k else 0)
        return cls(tuple(d["models"]), np.asarray(d["distances"], dtype=np.float64).reshape(k, m),
                   tuple(int(n) for n in d["curve_sizes"]), float(d["rho"]), float(d.get("noise", 0.0)),
                   tuple(float(x) for x in d.get("limits", ())), tuple(int(n) for n in d.get("touches", ())), misses,
                   float(d.get("resolution", 0.0)), tuple(float(x) for x in d.get("radii", ())),
                   int(d.get("tied", 1)), str(d.get("kind", "curves")))


def evidence(models: Sequence[str], signed: Sequence[np.ndarray], curve_sizes: Sequence[int],
             noise: float = 0.0, *, limits: Sequence[float] = (), touches: Sequence[int] = (),
             misses=None, resolution: float = 0.0, radii: Sequence[float] = (), tied: int = 1,
             kind: str = "curves") -> Evidence:
    """The :class:`Evidence` from each accepted model's signed residuals ``(m,)`` (best model first;
    curves in order, ``curve_sizes`` points each; the other arguments as its attributes)."""
    sizes = tuple(int(n) for n in curve_sizes)
    m = sum(sizes)
    rows = [np.abs(np.asarray(r, dtype=np.float64)) for r in signed]
    rho = lag_one(np.split(np.asarray(signed[0], dtype=np.float64), np.cumsum(sizes)[:-1])) if rows else 0.0
    return Evidence(tuple(models), np.array(rows).reshape(len(rows), m), sizes, float(rho), float(noise),
                    tuple(float(x) for x in limits), tuple(int(n) for n in touches), misses, float(resolution),
                    tuple(float(x) for x in radii), max(1, min(int(tied), len(rows))), str(kind))
