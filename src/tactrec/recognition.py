"""Recognition: which model the touch came from, and where (paper Section 3.3).

The touch's features are computed once (:class:`tactrec.features.Touch`);
the method (:mod:`tactrec.methods`) registers the data on the models and the
model with the smallest registration error ``E(M)`` is recognised (eq. 9).

A :class:`Recognizer` holds the models, prepared once, and the worker
processes a method's stages run in; :func:`recognize` is the one-off call,
in this process.
"""

from __future__ import annotations

import dataclasses
import functools
import multiprocessing
import time
from typing import Iterable

import numpy as np

from .errors import InputError
from .estimation import LocalGeometry
from .features import Touch
from .io.meeting import MEETING, meeting, meeting_points
from .io.touch import TactileData
from .methods import DEFAULT_METHOD, get_method
from .outliers import ALPHA, judge_ends
from .probability import AMBIGUOUS, UNKNOWN_PRIOR, Evidence, evidence, fit_limit, residuals, resolution
from .registration.result import Registration
from .runner import _Held, _Pool, _Serial, default_workers
from .tables import CurvatureTable
from .units import conversion

__all__ = ["Recognition", "Recognizer", "recognize", "ModelEntry", "default_workers"]


@dataclasses.dataclass(frozen=True)
class ModelEntry:
    """A model with its lookup table, ready for recognition."""

    model: object
    table: CurvatureTable

    @property
    def name(self) -> str:
        return self.model.name


@dataclasses.dataclass(frozen=True)
class Recognition:
    """Outcome of recognising one touch against a set of models.

    Attributes
    ----------
    best : str or None
        Name of the recognised model (``None`` if every model was rejected).
    ranking : list of Registration
        Sorted by error (data units), rejected models last.
    estimate : LocalGeometry
        Contact, normal and principal curvatures estimated from the data.
    seconds : float
        Wall time of the recognition, its probabilities included.
    method : str
    evidence : Evidence or None
        What the probabilities come from (:mod:`tactrec.probability`): each data point's distance
        to each accepted model under its pose.
    settled : bool
        False when the method's search ended on its budget rather than by its own rule.
    work : int
        The method's work (``fast``: closest-point queries).
    depth : int
        How many steps of its schedule the method's search ran.
    touch : Touch or None
        The touch as recognition saw it (points, estimate, noise), for callers that go on with it.
    allowed : int or None
        The most work the search's schedule could spend (``fast``: its budget, its grids about a
        stall up to as much again; None for a method without one).
    unknown_prior : float
        The prior probability that the touch came from none of the models (:mod:`tactrec.probability`).
    chance : NullModel or None
        The database's null model of chance fits (:mod:`tactrec.chance`), None where it has none:
        then ``unknown`` comes from the fit test alone.
    """

    best: str | None
    ranking: list[Registration]
    estimate: LocalGeometry
    seconds: float
    method: str
    evidence: Evidence | None = None
    settled: bool = True
    work: int = 0
    depth: int = 1
    touch: Touch | None = None
    allowed: int | None = None
    unknown_prior: float = UNKNOWN_PRIOR
    chance: object = None

    @functools.cached_property
    def _outcomes(self) -> tuple[dict[str, float], float]:
        if self.evidence is None:
            return {}, 1.0 if self.best is None else 0.0
        return self.evidence.named_outcomes(prior=self.unknown_prior, chance=self.chance)

    @property
    def probabilities(self) -> dict[str, float]:
        """Each accepted model's probability that the data came from it (with :attr:`unknown`, sum 1;
        see :mod:`tactrec.probability`)."""
        return self._outcomes[0]

    @property
    def unknown(self) -> float:
        """The probability that the data came from none of the models (docs/formats.md)."""
        return self._outcomes[1]

    @property
    def confidence(self) -> float:
        """The best model's probability (0 when every model was rejected)."""
        return float(self.probabilities.get(self.best, 0.0)) if self.best is not None else 0.0

    @property
    def ambiguous(self) -> bool:
        """True exactly when :attr:`confidence` is below :data:`~tactrec.probability.AMBIGUOUS`
        (docs/formats.md); False when every model was rejected.  A search that ended on its budget
        says so in :attr:`settled`."""
        if self.best is None:
            return False
        return bool(self.confidence < AMBIGUOUS)

    @property
    def located(self) -> bool:
        """False when the data leave the contact free on the best model (its ``spread`` exceeds
        :data:`LOCATED` x its error: a direction the data do not constrain, along a cylinder or
        over a flat patch)."""
        r = self.registration
        return r is None or not r.spread > LOCATED * r.error

    @property
    def outliers(self) -> int:
        """How many of the touch's points were set aside (:mod:`tactrec.outliers`; 0 without a touch)."""
        return int(self.touch.outliers) if self.touch is not None else 0

    @functools.cached_property
    def meeting(self) -> float:
        """How far the curves pass from their meeting point: the largest distance of a curve (of the
        points kept) from it, data units (0 without a touch; :func:`tactrec.io.meeting.meeting`)."""
        return float(meeting(self.touch.data)[1].max()) if self.touch is not None else 0.0

    @property
    def registration(self) -> Registration | None:
        return self.ranking[0] if self.ranking and self.ranking[0].ok else None

    def to_json(self) -> dict:
        """The result of docs/formats.md (``tactrec recognize --json``)."""
        return {
            "best": self.best,
            "ranking": [dict(r.to_json(), probability=self.probabilities[r.model]) if r.ok else r.to_json()
                        for r in self.ranking],
            "contact": self.estimate.contact.tolist(),
            "normal": (self.estimate.normal * (self.registration.normal_sign if self.registration else 1)).tolist(),
            "curvatures": [self.estimate.k1, self.estimate.k2],
            "method": self.method,
            "confidence": self.confidence,
            "unknown": self.unknown,
            "calibrated": self.chance is not None,
            "ambiguous": self.ambiguous,
            "located": self.located,
            "settled": self.settled,
            "outliers": self.outliers,
            "meeting": self.meeting,
            "seconds": round(self.seconds, 4),
        }


#: a touch this many times larger than every model, or smaller than every one, is in the wrong units
OFF_SCALE = 1000.0


def _check_scale(data: TactileData, models) -> None:
    """Refuse, before any arithmetic on it, a touch whose extent (in each model's units) is more than
    :data:`OFF_SCALE` times every model's size, or less than every model's size over it."""
    points = data.points
    extent = float(np.max(points.max(axis=0) - points.min(axis=0)))
    ratios = [extent * conversion(data.units, getattr(e.model, "units", None)) / e.model.size for e in models]
    if not ratios or OFF_SCALE ** -1 <= max(ratios) and min(ratios) <= OFF_SCALE:
        return
    sizes = [e.model.size for e in models]
    span = f"{min(sizes):.3g}" if min(sizes) == max(sizes) else f"{min(sizes):.3g}-{max(sizes):.3g}"
    where = f"over {OFF_SCALE:g} times" if min(ratios) > OFF_SCALE else f"under 1/{OFF_SCALE:g} of"
    kinds = {getattr(e.model, "units", None) for e in models}
    model_units = (kinds.pop() or "units") if len(kinds) == 1 else "in their own units"
    raise InputError(f"the touch spans {extent:.3g} {data.units or 'units'}, {where} every model's size "
                     f"({span} {model_units}): are its units right?", data.source)


#: on noise-free data a fit is within this fraction of the touch's radius, for a method without a ``floor`` of its own
FLOOR = 1e-3
#: the data leave the contact free when its spread (the root of the trace of its covariance under the
#: fit) exceeds this many times the fit's mean residual: the dilution of precision of a direction
#: the data do not constrain (on YCB scans, the median is 3 for P3 touches and 6 for hard ones)
LOCATED = 10.0


def _missing(touch: Touch) -> bool:
    """Whether the touch's curves miss each other: a curve passes its meeting point farther than its
    noise allows (``k`` sigma, ``k = sqrt(2 ln(m / ALPHA))`` for ``m`` points, as
    :mod:`tactrec.outliers` bounds them).  Curves that pass through one point were traced there."""
    k = np.sqrt(2.0 * np.log(max(len(touch.points), 1) / ALPHA))
    return bool(meeting(touch.data)[1].max() > k * touch.noise)


def _best_error(outcome) -> float:
    """The least error of an outcome's accepted registrations, data units (inf for none)."""
    return min((r.error / r.scale for r in outcome.ranking if r.ok), default=np.inf)


def _rank_key(r: Registration):
    """Accepted models first, by error in the data's units (models may differ in units)."""
    return (not r.ok, r.error / r.scale if r.ok else 0.0, r.model)


class Recognizer:
    """Recognises touches against one set of models, keeping what it builds between touches.

    Parameters
    ----------
    models : iterable of ModelEntry
        Models with their lookup tables (see :mod:`tactrec.database`).
    method : str
        ``"fast"`` (the default) or ``"paper"``.
    workers : int
        Processes a method's stages run in (1: this process; the result is the same).  Forked
        once, after the models are prepared, and ended by :meth:`close` or the ``with`` block.
    window, degree, curvature_method
        Passed to :func:`tactrec.estimation.estimate`.
    unknown_prior : float
        The prior probability that a touch came from none of the models, in [0, 1)
        (:data:`~tactrec.probability.UNKNOWN_PRIOR`; 0: a closed world).
    chance : NullModel, None or False
        The models' null model of chance fits (:mod:`tactrec.chance`), fitted on these models for
        this method; None: a database's own, where it holds one; False: none, ``unknown`` from the
        fit test alone.
    tips : iterable of float
        Radii of round tips (the models' units) whose offset fields every mesh prepares now, before
        the workers fork (:mod:`tactrec.surfaces.mesh_offset`: read from the stored fields up to
        10 mm, built beyond), so that no recognition reads or builds them.
    **options
        The method's options (its :class:`~tactrec.methods.base.Config`); a name it does not
        know is an :class:`~tactrec.errors.InputError`.
    """

    def __init__(self, models: Iterable[ModelEntry], *, method: str = DEFAULT_METHOD, workers: int = 1,
                 window: int | str | None = "auto", degree: int = 3, curvature_method: str = "auto",
                 unknown_prior: float = UNKNOWN_PRIOR, chance=None, tips: Iterable[float] = (), **options):
        if not (isinstance(unknown_prior, (int, float)) and 0.0 <= unknown_prior < 1.0):
            raise InputError(f"the prior of unknown must be a number in [0, 1), not {unknown_prior!r}", "unknown_prior")
        self.unknown_prior = float(unknown_prior)
        self.method = get_method(method)
        self.config = self.method.configure(**options)
        stored = getattr(models, "chance", None)          # a database's own
        self.models = list(models)
        from .chance import chosen

        self.chance = chosen(self.models, chance, self.method.name, stored)
        self._by_name = {entry.name: entry for entry in self.models}
        self.estimation = dict(window=window, degree=degree, curvature_method=curvature_method)
        tips = tuple(float(r) for r in tips)
        if not all(np.isfinite(r) and r > 0 for r in tips):
            raise InputError(f"a tip radius is a positive number (got {tips})", "tips")
        for entry in self.models:
            self.method.prepare(entry.model)
            for r in tips if entry.model.kind == "mesh" else ():
                entry.model.offset(float(r)).distance_field
        if self.method.uses_engine:
            from .engine.kernels import warm

            warm()         # compiled or loaded now, not in a recognition's seconds; forked workers inherit it
        held = _Held(self.models)
        # not from inside another process's worker (a benchmark running touches in parallel):
        # forking there can deadlock, and that pool already uses the cores
        nested = multiprocessing.parent_process() is not None
        if int(workers) >= 2 and not nested and "fork" in multiprocessing.get_all_start_methods():
            self.runner = _Pool(held, int(workers))
        else:
            self.runner = _Serial(held)

    def __enter__(self) -> "Recognizer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """End the worker processes."""
        if isinstance(self.runner, _Pool):
            self.runner.close()

    def session(self, **options):
        """A new :class:`~tactrec.session.Session` of touches of one object, recognised with these
        models (nothing is rebuilt between touches); ``options`` are the session's keywords
        (``search_budget``, ``joint_search``)."""
        from .session import Session

        return Session(self, **options)

    def recognize(self, data: TactileData, *, context=(), among=None, fit: float = 0.0,
                  budget: int | None = None, context_tips=None, context_surface=None) -> Recognition:
        """Recognise one touch (Section 3.3).  ``context``: curves of other touches of the same object
        in the same frame, which the poses must fit too (a method that searches from this touch's
        local geometry scores its poses on them; see :class:`~tactrec.features.Touch`), and ``fit``
        the mean distance over all those points that counts as a fit (0: this touch's own limit).
        ``among``: the names of the models to search (None: all); the others are rejected as not
        searched.  ``budget``: the most work (closest-point queries) the search may spend in all, when
        lower than the method's own budget; the first round runs whatever it costs (a touch with outliers
        is searched within it without its curves' ends, then refitted: :func:`tactrec.outliers.judge_ends`).  ``context_tips``:
        the tip radius of each context curve and ``context_surface`` the curves moved onto the surface
        (:mod:`tactrec.tip`; None: no tip).

        Where the data give no ``contact``, the curves' meeting point is :func:`~tactrec.io.meeting.find_contact`'s.
        Curves that miss each other (beyond their noise) may meet at more than one point within the
        tolerance (:func:`~tactrec.io.meeting.meeting_points`: the far face of a thin plate); where the
        search from the first finds no fit, each other is searched in turn, the best error kept,
        until one fits or ``budget`` is spent.  Curves that pass through one point were traced there."""
        start = time.perf_counter()
        _check_scale(data, self.models)
        chosen = None
        if among is not None:
            unknown = sorted(set(among) - set(self._by_name))
            if unknown:
                raise InputError(f"no model named {unknown[0]!r} among the recognizer's", "among")
            chosen = [i for i, entry in enumerate(self.models) if entry.name in set(among)]

        def refit(outcome, t):
            return self.method.refit(t, self.models, self.config, self.runner, outcome)

        def searched(d, left):
            def search(t):
                return self.method.search(t, self.models, self.config, self.runner, among=chosen, budget=left)
            touch = Touch.from_data(d, **self.estimation)
            if len(context):
                touch = touch.with_context(context, fit=fit, tips=context_tips, surface=context_surface)
            if touch.outliers and not len(context):     # a slipping sensor: its curves' ends judged by the fit
                return judge_ends(touch, search, refit, self._residuals, self.estimation)
            return touch, search(touch)

        touch, outcome = searched(data, budget)
        if data.contact is None and not self._fits(touch, outcome) and _missing(touch):
            # curves that miss each other may meet elsewhere too (a thin plate's far face): each
            # meeting point, closest first, is tried until one's best fits
            for contact in meeting_points(touch.data.curves, MEETING * touch.data.spacing)[1:]:
                left = None if budget is None else budget - outcome.work
                if left is not None and left <= 0:
                    break
                try:
                    other, found = searched(dataclasses.replace(data, contact=contact), left)
                except InputError:                 # no estimate there (curves tangent at it): not the contact
                    continue
                work = outcome.work + found.work
                allowed = None if outcome.allowed is None or found.allowed is None else outcome.allowed + found.allowed
                if _best_error(found) < _best_error(outcome):
                    touch, outcome = other, found
                outcome = dataclasses.replace(outcome, work=work, allowed=allowed)
                if self._fits(touch, outcome):
                    break
        ranking = sorted(outcome.ranking, key=_rank_key)
        best = ranking[0].model if ranking and ranking[0].ok else None
        ok = [r for r in ranking if r.ok]
        limit = max(fit_limit(touch, self.floor), touch.fit)
        found = evidence([r.model for r in ok], [self._residuals(r, touch) for r in ok],
                         [len(c) for c in touch.joint_curves], touch.noise, limits=(limit,),
                         resolution=resolution(touch, self.floor), radii=(touch.radius,))
        out = Recognition(best, ranking, touch.estimate, 0.0, self.method.name, found, outcome.settled, outcome.work,
                          outcome.depth, touch, outcome.allowed, self.unknown_prior, self.chance)
        out.probabilities                        # the probabilities are part of the recognition and of its seconds
        object.__setattr__(out, "seconds", time.perf_counter() - start)          # set once, before anyone sees it
        return out

    def _fits(self, touch: Touch, outcome) -> bool:
        """Whether the best registration of ``outcome`` fits ``touch`` (within its fit limit)."""
        return _best_error(outcome) <= max(fit_limit(touch, self.floor), touch.fit)

    @property
    def floor(self) -> float:
        """The method's ``floor`` (a fit's mean distance per unit radius on noise-free data), or
        :data:`FLOOR` for a method without one."""
        return float(getattr(self.config, "floor", FLOOR))

    def _residuals(self, r: Registration, touch: Touch) -> np.ndarray:
        """The data's signed distances (data units) to the model of ``r`` under its pose (to the model
        offset by each point's tip: :mod:`tactrec.tip`)."""
        model = touch.in_units(r.scale).exact(self._by_name[r.model].model)
        return residuals(model, r.rotation, r.translation, touch.joint_points, r.scale)


def recognize(data: TactileData, models: Iterable[ModelEntry], *, method: str = DEFAULT_METHOD, workers: int = 1,
              window: int | str | None = "auto", degree: int = 3, curvature_method: str = "auto",
              **options) -> Recognition:
    """Recognise one touch against ``models`` (Section 3.3): a one-off :class:`Recognizer`.

    For many touches against the same models, keep a :class:`Recognizer` instead: it prepares
    the models and starts its worker processes once.
    """
    with Recognizer(models, method=method, workers=workers, window=window, degree=degree,
                    curvature_method=curvature_method, **options) as recognizer:
        return recognizer.recognize(data)
