"""The null model of chance fits: how likely a touch's fits are to come from an object the
database does not hold.

A touch may fit a model within its noise because it touched that model, or because a small,
noisy touch fits an unrelated surface (a flat patch fits every flat face, a patch of one fruit
another fruit).  How often the second happens depends on the touch (how much surface it spans
against its noise) and on the catalogue (how alike its models are), so it is measured on the
catalogue itself, the way a sequence search measures the chance hits behind its E-values
(:mod:`.fit`): seeded touches of each model are recognised twice, once with the whole database
(*known*: the touched model is in it) and once with the touched model left out (*unknown*: the
touch is of an object the database does not hold).

Each recognition gives two statistics, the best model's fit ``x1`` and the second best's ``x2``
(:func:`statistic`: ``log10`` of the mean distance over the fit limit,
:func:`tactrec.probability.fit_limit`, clipped to ``[-2, 2]``; ``x2 = 2`` without a second
model; a mean distance below the touch's resolution, :func:`tactrec.probability.resolution`, is
read as at it, so that all fits closer than the data can tell are one evidence), and each touch
its resolving power ``r = log10(radius / fit limit)``.  A chance fit is
seldom alone: where the touched model fits, the others usually fit much worse (``x2 - x1``
large); where an unrelated model fits by chance, others usually fit nearly as well.

For a new touch, the likelihood ratio of known against unknown (:meth:`NullModel.ratio`) is a
logistic regression's odds between the two classes, on the best fit ``x1`` and its lead over the
second ``x2 - x1``, fitted over the calibration touches nearest the touch in ``r``
(:data:`NEAREST`; each gives one known and one unknown, so the odds are the likelihood ratio).
The regression is smooth where the touches are few and monotone where the evidence is (:data:`SIGNS`:
a slope of the wrong sign is dropped); each standardised slope has a Gaussian prior, so that
classes the touches separate completely do not run to infinity, whose precision the calibration
touches choose themselves (:attr:`NullModel.penalty`: of :data:`PENALTIES`, the one under which
each model's touches are predicted best by the other models'); a touch beyond every calibration
touch is read as the farthest of them; and the ratio is held within ``1 / (k + 1)`` and ``k + 1``
over ``k`` touches: no ratio claims more than that many calibration touches can show.
A touch more (less) resolving than every calibration touch is read with the most (least)
resolving of them.  :func:`tactrec.probability.open_world` turns the ratio into ``unknown``'s
probability and the models'.

Each kind of touch is weighed against calibration touches of its own kind (:data:`KINDS`): a patch
of 400 points over a few millimetres, a curve of 61 points over centimetres and a handful of single
contacts fit unrelated surfaces by chance at different rates for the same statistics.  Where the
calibration holds fewer than :data:`NEAREST` touches of a touch's kind (a session of mixed kinds, a
kind the catalogue was not calibrated for) it is weighed against all of them.

The model is stored with the database (:data:`FILE`, plain JSON, keyed by the models' content:
:func:`catalogue_key`) and fitted again when the models change (``tactrec calibrate``).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import write_text_atomic

__all__ = ["NullModel", "SIGNS", "chosen", "statistic", "statistics", "catalogue_key", "load", "save", "FILE",
           "FORMAT", "VERSION", "NEAREST", "PENALTIES", "SPAN", "KINDS"]

FORMAT, VERSION = "tactrec-chance", 1
#: the null model's file in a database folder
FILE = "chance.json"
#: a touch's ratio is fitted over at least this many calibration touches, the nearest in resolving
#: power, or a quarter of them where that is more
NEAREST = 20
#: the slopes' prior precisions (on standardised features) cross-validation chooses among: from a unit
#: prior to one a hundred times wider
PENALTIES = (1.0, 0.3, 0.1, 0.03, 0.01)
#: the statistics' range: a fit this many decades better or worse than its limit reads as at the end
SPAN = 2.0
#: the kinds of touch a calibration touch may be (:attr:`tactrec.io.touch.TactileData.kind`)
KINDS = ("curves", "patch", "contacts")


def statistic(mean, limit):
    """``log10(mean / limit)`` clipped to ``[-SPAN, SPAN]`` (element-wise): how a mean distance
    compares with the fit limit, 0 at the limit."""
    mean = np.maximum(np.asarray(mean, dtype=np.float64), 0.0)
    with np.errstate(divide="ignore"):
        return np.clip(np.log10(mean / float(limit)), -SPAN, SPAN)


def statistics(evidence) -> tuple[float, float, float]:
    """``(x1, x2, r)`` of a recognition's :class:`~tactrec.probability.Evidence` (module text): the best
    two models' fits, each its mean distance over every point (read as the evidence's ``resolution``
    where closer) against the points-weighted mean of the touches' limits (:func:`statistic`), and the
    touches' median resolving power ``log10(radius / limit)``."""
    points = evidence.touch_points()
    total = max(int(points.sum()), 1)
    limit = float((np.asarray(evidence.limits) * points).sum() / total)          # element-wise: no BLAS
    # a fit closer than the resolution is read as at it (module text): all such fits are one evidence
    means = np.maximum(np.sort(evidence.distances.sum(axis=1) / total)[:2], evidence.resolution)
    x = [float(statistic(v, limit)) for v in means] + [SPAN] * (2 - len(means))
    r = float(np.median(np.log10(np.asarray(evidence.radii, dtype=np.float64) / np.asarray(evidence.limits))))
    return x[0], x[1], r


def _fingerprint(model) -> str:
    """A hash of what a model is: a mesh's vertices and faces, else its stored arrays."""
    h = hashlib.sha256()
    h.update(f"{model.name}\0{model.kind}\0".encode())
    if hasattr(model, "vertices") and hasattr(model, "faces"):
        arrays = {"vertices": model.vertices, "faces": model.faces}
    else:
        arrays = model.to_store()
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key])
        h.update(f"{key}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def catalogue_key(entries) -> str:
    """The models' content hash (their order aside): a null model fitted on other models is not used."""
    h = hashlib.sha256()
    for fingerprint in sorted(_fingerprint(e.model) for e in entries):
        h.update(fingerprint.encode())
    return h.hexdigest()


def _solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a^-1 b`` for a small symmetric positive definite ``a``, by Gaussian elimination in plain
    arithmetic: the same digits under every BLAS kernel."""
    a = a.astype(np.float64).copy()
    b = b.astype(np.float64).copy()
    n = len(b)
    for i in range(n):
        for j in range(i + 1, n):
            f = a[j, i] / a[i, i]
            a[j, i:] = a[j, i:] - f * a[i, i:]
            b[j] = b[j] - f * b[i]
    x = np.zeros(n)
    for i in range(n - 1, -1, -1):
        x[i] = (b[i] - float((a[i, i + 1:] * x[i + 1:]).sum())) / a[i, i]
    return x


def _logistic(x: np.ndarray, y: np.ndarray, penalty: float) -> np.ndarray:
    """Coefficients ``(1 + d,)`` of a logistic regression of ``y (n,)`` (0 or 1) on ``[1, x]`` (``x (n, d)``,
    standardised), each slope with a Gaussian prior of precision ``penalty``: Newton's steps to
    convergence, in element-wise sums (no BLAS)."""
    z = np.column_stack([np.ones(len(x)), x])
    d = z.shape[1]
    prior = np.array([0.0] + [float(penalty)] * (d - 1))
    w = np.zeros(d)
    for _ in range(100):
        p = 1.0 / (1.0 + np.exp(-np.clip((z * w).sum(axis=1), -30.0, 30.0)))
        grad = (z * (p - y)[:, None]).sum(axis=0) + prior * w
        s = p * (1.0 - p)
        hess = np.array([[float((z[:, i] * z[:, j] * s).sum()) for j in range(d)] for i in range(d)]) + np.diag(prior)
        step = _solve(hess, grad)
        w = w - step
        if np.abs(step).max() < 1e-12:
            break
    return w


#: the sign each slope must have: a worse best fit is never more evidence for a model, a larger
#: lead over the second never less
SIGNS = (-1.0, 1.0)


def _ratios(resolving, known, unknown, r: float, queries, penalty: float) -> np.ndarray:
    """:meth:`NullModel.ratio` at resolving power ``r`` of each of ``queries (m, 2)`` (``x1, x2``), over
    the calibration touches ``resolving (n,)``, ``known, unknown (n, 2)``, slopes with a prior of
    precision ``penalty`` (one fit for them all); 1 without touches."""
    queries = np.asarray(queries, dtype=np.float64).reshape(-1, 2)
    n = len(resolving)
    if n == 0:
        return np.ones(len(queries))
    k = min(n, max(NEAREST, n // 4))
    near = np.argsort(np.abs(resolving - float(r)), kind="stable")[:k]

    def features(s):
        return np.column_stack([s[:, 0], s[:, 1] - s[:, 0]])

    x = np.vstack([features(known[near]), features(unknown[near])])
    y = np.concatenate([np.ones(k), np.zeros(k)])
    # a touch beyond every calibration touch is read as the farthest of them
    q = np.clip(features(queries), x.min(axis=0), x.max(axis=0))
    use = [0, 1]
    while True:                     # a slope of the wrong sign is dropped and the rest fitted again
        centre = x[:, use].mean(axis=0)
        scale = x[:, use].std(axis=0) + 1e-6
        w = _logistic((x[:, use] - centre) / scale, y, penalty)
        wrong = [f for f, c in zip(use, w[1:]) if c * SIGNS[f] < 0.0]
        if not wrong:
            break
        use = [f for f in use if f not in wrong]
    logit = w[0] + (w[1:] * (q[:, use] - centre) / scale).sum(axis=1)
    cap = np.log(k + 1.0)
    return np.exp(np.clip(logit, -cap, cap))


@dataclasses.dataclass(frozen=True)
class NullModel:
    """Calibration touches' statistics (module text).

    Attributes
    ----------
    key : str
        :func:`catalogue_key` of the models it was fitted on.
    resolving : (n,) float
        Each calibration touch's resolving power ``r``.
    known, unknown : (n, 2) float
        Each touch's ``(x1, x2)`` with the touched model in the database, and left out.
    touched : tuple of str
        Each touch's model (:meth:`without` leaves a model's touches out).
    kinds : tuple of str
        Each touch's kind (:data:`KINDS`; empty: all curves).
    method : str
        The method whose fits were calibrated (a recognizer of another does not use it).
    seed, touches : int
        The calibration's seed and touches per model.
    fitted_penalty : float or None
        The prior's precision as chosen when it was fitted (:attr:`penalty`; None: chosen when read).
    """

    key: str
    resolving: np.ndarray
    known: np.ndarray
    unknown: np.ndarray
    touched: tuple = ()
    method: str = "fast"
    seed: int = 0
    touches: int = 0
    fitted_penalty: float | None = None
    kinds: tuple = ()

    def __len__(self) -> int:
        return len(self.resolving)

    def without(self, names) -> "NullModel":
        """The null model of the calibration touches of models other than ``names``: a database that
        leaves those models out is scored without having seen them (made once per ``names``)."""
        leave = tuple(sorted(set(names)))
        if leave not in self._left:
            keep = np.array([t not in leave for t in self.touched], dtype=bool)
            self._left[leave] = dataclasses.replace(
                self, resolving=self.resolving[keep], known=self.known[keep], unknown=self.unknown[keep],
                touched=tuple(np.array(self.touched)[keep].tolist()), key=f"{self.key} without {','.join(leave)}",
                fitted_penalty=None, kinds=tuple(np.array(self.kind_of)[keep].tolist()))
        return self._left[leave]

    @functools.cached_property
    def _left(self) -> dict:
        """:meth:`without`'s models, by the names left out (each chooses its prior once)."""
        return {}

    @property
    def kind_of(self) -> tuple:
        """Each calibration touch's kind (all curves where the file names none)."""
        return self.kinds or ("curves",) * len(self)

    def pool(self, kind: str, among=None) -> np.ndarray:
        """The calibration touches (indices, of ``among``: a boolean mask, default all) a touch of
        ``kind`` is weighed against: those of its kind where there are :data:`NEAREST` of them, else all."""
        among = np.ones(len(self), dtype=bool) if among is None else np.asarray(among, dtype=bool)
        same = among & (np.array(self.kind_of, dtype=object) == kind)
        return np.flatnonzero(same if same.sum() >= NEAREST else among)

    def ratio_of(self, evidence) -> float:
        """:meth:`ratio` of a recognition's evidence (its :func:`statistics` and kind)."""
        return self.ratio(*statistics(evidence), kind=getattr(evidence, "kind", "curves"))

    def ratio(self, x1: float, x2: float, resolving: float, kind: str = "curves") -> float:
        """The likelihood ratio, known against unknown, of a touch of ``kind`` whose best two fits are
        ``x1`` and ``x2`` (:func:`statistic`) and whose resolving power is ``resolving`` (module text); 1
        (no evidence either way) for statistics that are not finite."""
        if not np.isfinite([x1, x2, resolving]).all():
            return 1.0
        i = self.pool(kind)
        return float(_ratios(self.resolving[i], self.known[i], self.unknown[i], resolving, [(x1, x2)],
                             self.penalty)[0])

    @functools.cached_property
    def penalty(self) -> float:
        """The slopes' prior precision: of :data:`PENALTIES`, the one whose ratios predict the
        calibration touches best (the mean log-likelihood of their known and unknown recognitions),
        each model's touches from the other models' alone (of the touch's kind, :meth:`pool`), as a touch
        of an object the calibration never saw would be; the first (the most cautious) of equals."""
        if self.fitted_penalty is not None:
            return float(self.fitted_penalty)
        names = np.array(self.touched)
        if len(set(self.touched)) < 2:
            return PENALTIES[0]
        scores = []
        for penalty in PENALTIES:
            total = 0.0
            for t in range(len(self)):
                keep = self.pool(self.kind_of[t], names != names[t])
                lr = _ratios(self.resolving[keep], self.known[keep], self.unknown[keep], self.resolving[t],
                             [self.known[t], self.unknown[t]], penalty)
                total += float(np.log(lr[0] / (1.0 + lr[0])) + np.log(1.0 / (1.0 + lr[1])))
            scores.append(round(total / (2 * len(self)), 9))      # equal to within rounding is equal
        return PENALTIES[int(np.argmax(scores))]

    def to_json(self) -> dict:
        return {"format": FORMAT, "version": VERSION, "key": self.key, "method": self.method, "seed": int(self.seed),
                "touches": int(self.touches), "resolving": np.round(self.resolving, 6).tolist(),
                "known": np.round(self.known, 6).tolist(), "unknown": np.round(self.unknown, 6).tolist(),
                "touched": list(self.touched), "kinds": list(self.kind_of), "penalty": self.penalty}

    @classmethod
    def from_json(cls, d, source) -> "NullModel":
        """From :meth:`to_json`'s dict; an :class:`InputError` naming ``source`` where it is not one."""
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise InputError("not a tactrec null model of chance fits", source)
        if d.get("version") != VERSION:
            raise InputError(f"null model version {d.get('version')!r}, this tactrec reads {VERSION}: "
                             "run 'tactrec calibrate' again", source)
        try:
            r = np.asarray(d["resolving"], dtype=np.float64).reshape(-1)
            known = np.asarray(d["known"], dtype=np.float64).reshape(len(r), 2)
            unknown = np.asarray(d["unknown"], dtype=np.float64).reshape(len(r), 2)
            touched = tuple(str(t) for t in d["touched"])
            kinds = tuple(str(k) for k in d.get("kinds", ("curves",) * len(touched)))
            key, method, seed, touches = str(d["key"]), str(d["method"]), int(d["seed"]), int(d["touches"])
            fitted = d.get("penalty")
            if fitted is not None and (isinstance(fitted, bool) or not isinstance(fitted, (int, float))):
                raise TypeError("penalty")
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise InputError(f"corrupted null model ({exc.__class__.__name__})", source) from None
        if len(touched) != len(r) or len(kinds) != len(r):
            raise InputError("corrupted null model (a touch without its model or kind)", source)
        if not set(kinds) <= set(KINDS):
            raise InputError(f"corrupted null model (a touch of kind {sorted(set(kinds) - set(KINDS))[0]!r})", source)
        if not (np.isfinite(r).all() and np.isfinite(known).all() and np.isfinite(unknown).all()):
            raise InputError("corrupted null model (a value is not finite)", source)
        if fitted is not None and float(fitted) not in PENALTIES:
            fitted = None                       # a precision this version does not offer: chosen again
        return cls(key, r, known, unknown, touched, method, seed, touches, fitted, kinds)


def save(model: NullModel, folder: str | os.PathLike) -> Path:
    """Write ``model`` into the database ``folder`` (atomically); returns the file."""
    path = Path(folder) / FILE
    write_text_atomic(path, json.dumps(model.to_json()) + "\n")
    return path


def load(folder: str | os.PathLike, key: str | None = None) -> NullModel | None:
    """The null model stored in the database ``folder``, or None where there is none or (``key``
    given) it was fitted on other models; a damaged file is an :class:`InputError`."""
    path = Path(folder) / FILE
    if not path.is_file():
        return None
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:                     # unreadable, not text, not JSON
        raise InputError(f"corrupted null model ({exc.__class__.__name__})", path) from None
    model = NullModel.from_json(d, path)
    return model if key is None or model.key == key else None


def chosen(entries, chance, method: str, stored: NullModel | None = None) -> NullModel | None:
    """The null model a recognizer of ``entries`` by ``method`` uses: ``chance`` (False: none), else
    (None) ``stored``, the database's own, where it was fitted for this method; one given that was
    fitted on other models or for another method is an :class:`InputError`."""
    if chance is False:
        return None
    if chance is None:
        return stored if stored is not None and stored.method == method else None
    if chance.key != catalogue_key(entries):
        raise InputError("the null model of chance fits was fitted on other models", "chance")
    if chance.method != method:
        raise InputError(f"the null model of chance fits is {chance.method!r}'s, not {method!r}'s", "chance")
    return chance
