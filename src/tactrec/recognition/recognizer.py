"""The one path from a touch to a result (paper Section 3.3): :class:`Recognizer`.

A :class:`Recognizer` holds the models, each prepared once (by the worker
process that runs its stages, where there are workers); :func:`recognize` is the one-off call,
in this process.  A recognition of tactile data:

1. refuses a touch in the wrong units (:func:`check_scale`);
2. computes the touch's features once (:class:`tactrec.features.Touch`: its
   points off their curves' traces set aside, the estimate at the contact,
   the noise), with the other touches of a session scored too where it has a
   :class:`~tactrec.features.Context`;
3. runs the method's search (:mod:`tactrec.methods`) over the models; where the
   sensor slipped, the curves' ends are judged by the fit, and where curves
   that miss each other meet at another point too, that one is searched as well
   (:mod:`.again`);
4. ranks the registrations by error (eq. 9) and weighs them into probabilities
   (:mod:`tactrec.probability`): the :class:`~.result.Recognition`.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Iterable

import numpy as np

from ..errors import InputError
from ..features import Context, Touch
from ..io.touch import TactileData
from ..methods import DEFAULT_METHOD, get_method
from ..probability import AMBIGUOUS, FLOOR, UNKNOWN_PRIOR, evidence, fit_limit, plausible_fit, residuals, resolution
from ..methods.base import NOT_SEARCHED, SearchOutcome
from ..registration.result import Outcome, Registration
from ..runner import Held, Pool, Serial, can_fork
from ..tables import CurvatureTable
from ..units import conversion
from .again import best_error, judge_ends, missing, other_meetings
from .places import other_places, place_share, place_stage
from .result import Recognition

__all__ = ["Recognizer", "recognize", "ModelEntry", "check_scale", "OFF_SCALE"]


@dataclasses.dataclass(frozen=True)
class ModelEntry:
    """A model with its lookup table, ready for recognition; ``stored``, where it was loaded from a
    database, is that folder and the model's entry in its index (what a cluster's workers load:
    :mod:`tactrec.cluster`)."""

    model: object
    table: CurvatureTable
    stored: tuple | None = dataclasses.field(default=None, compare=False, repr=False)

    @property
    def name(self) -> str:
        return self.model.name


#: a touch this many times larger than every model, or smaller than every one, is in the wrong units
OFF_SCALE = 1000.0


def check_scale(data: TactileData, models) -> None:
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
        once, and ended by :meth:`close` or the ``with`` block; model ``i`` belongs to worker
        ``i % workers``, which alone prepares it and runs its stages (:class:`~tactrec.runner.Pool`),
        so that each process holds its own share of the fields and trees.
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
        Radii of round tips (the models' units) whose offset fields every mesh prepares with it
        (:mod:`tactrec.surfaces.mesh_offset`: read from the stored fields up to
        10 mm, built beyond), so that no recognition reads or builds them.
    cluster : tactrec.cluster.Cluster, optional
        Run the stages on a Dask cluster's workers instead (:func:`tactrec.cluster.connect`; the
        models must come from a database, whose files the workers load and prepare, ``tips``
        included): the same results, and this process prepares no model (it may hold them
        without their distance fields: :func:`tactrec.database.load_database`).  ``workers`` is
        then unused.
    **options
        The method's options (its :class:`~tactrec.methods.base.Config`); a name it does not
        know is an :class:`~tactrec.errors.InputError`.
    """

    def __init__(self, models: Iterable[ModelEntry], *, method: str = DEFAULT_METHOD, workers: int = 1,
                 window: int | str | None = "auto", degree: int = 3, curvature_method: str = "auto",
                 unknown_prior: float = UNKNOWN_PRIOR, chance=None, tips: Iterable[float] = (), cluster=None,
                 **options):
        if not (isinstance(unknown_prior, (int, float)) and 0.0 <= unknown_prior < 1.0):
            raise InputError(f"the prior of unknown must be a number in [0, 1), not {unknown_prior!r}", "unknown_prior")
        self.unknown_prior = float(unknown_prior)
        self.method = get_method(method)
        self.config = self.method.configure(**options)
        stored = getattr(models, "chance", None)          # a database's own
        self.models = list(models)
        from ..chance import chosen

        self.chance = chosen(self.models, chance, self.method.name, stored)
        self._number = {entry.name: i for i, entry in enumerate(self.models)}
        self.estimation = dict(window=window, degree=degree, curvature_method=curvature_method)
        tips = tuple(float(r) for r in tips)
        if not all(np.isfinite(r) and r > 0 for r in tips):
            raise InputError(f"a tip radius is a positive number (got {tips})", "tips")
        def prepare(entry) -> None:
            self.method.prepare(entry.model)
            for r in tips if entry.model.kind == "mesh" else ():
                entry.model.offset(float(r)).distance_field

        pooled = cluster is None and int(workers) >= 2 and can_fork()
        for entry in self.models if cluster is None and not pooled else ():   # else its workers prepare their own
            prepare(entry)
        if self.method.uses_engine and cluster is None:
            from ..engine.kernels import warm

            warm()         # compiled or loaded now, not in a recognition's seconds; forked workers inherit it
        #: the catalogue's index of places (:mod:`tactrec.index`), for a method that ranks places by it
        self.index = None
        if getattr(self.method, "uses_index", False):
            from ..index import PlaceIndex

            self.index = PlaceIndex(self.models)
        if cluster is not None:
            self.runner = cluster.runner(self.models, method=self.method.name, tips=tips)
            return
        held = Held(self.models)
        self.runner = Pool(held, int(workers), prepare=prepare) if pooled else Serial(held)

    def __enter__(self) -> "Recognizer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """End the worker processes (on a cluster: let its workers forget these models)."""
        if hasattr(self.runner, "close"):
            self.runner.close()

    def session(self, **options):
        """A new :class:`~tactrec.session.Session` of touches of one object, recognised with these
        models (nothing is rebuilt between touches); ``options`` are the session's keywords
        (``search_budget``, ``joint_search``)."""
        from ..session import Session

        return Session(self, **options)

    def recognize(self, data: TactileData, *, among=None, budget: int | None = None) -> Recognition:
        """Recognise one touch (Section 3.3; the module text).  ``among``: the names of the models to
        search (None: all); the others are rejected as not searched.  ``budget``: the most work
        (closest-point queries) the search may spend in all, when lower than the method's own budget;
        the first round runs whatever it costs.

        Where the data give no ``contact``, the curves' meeting point is
        :func:`~tactrec.io.meeting.find_contact`'s, and curves that miss each other (beyond their
        noise) are searched from each other meeting point too until one fits or ``budget`` is spent
        (:func:`.again.other_meetings`).  A touch with outliers is searched without its curves' ends,
        then refitted (:func:`.again.judge_ends`).  A touch of single contacts is posed from triangles
        of its contacts (:mod:`tactrec.engine.contacts`; ``budget`` does not apply)."""
        return self._recognize(data, None, among, budget)

    def recognize_jointly(self, data: TactileData, context: Context, *, among=None,
                          budget: int | None = None) -> Recognition:
        """:meth:`recognize`, the poses scored also on ``context``'s curves (other touches of the same
        object, same frame: a session's step 5, :mod:`tactrec.session`), a method that searches from
        this touch's local geometry scoring its poses on them (:attr:`~tactrec.methods.base.Method.scores_context`);
        a fit is the context's ``fit`` where that is larger than this touch's own limit.  The ends of
        a touch with outliers are not judged again here: the session's touches were each judged alone."""
        return self._recognize(data, context, among, budget)

    def _recognize(self, data: TactileData, context: Context | None, among, budget: int | None) -> Recognition:
        start = time.perf_counter()
        check_scale(data, self.models)
        chosen = None
        if among is not None:
            unknown = sorted(set(among) - set(self._number))
            if unknown:
                raise InputError(f"no model named {unknown[0]!r} among the recognizer's", "among")
            chosen = [i for i, entry in enumerate(self.models) if entry.name in set(among)]

        def refit(outcome, t):
            return self.method.refit(t, self.models, self.config, self.runner, outcome)

        if data.contacts is not None:                  # single contacts: posed from their triangles
            return self._recognition(*self._contacts(data, chosen), start)

        def searched(d, left):
            def search(t):
                return self.method.search(t, self.models, self.config, self.runner, among=chosen, budget=left,
                                          index=self.index)
            touch = Touch.from_data(d, **self.estimation)
            if context is not None and len(context.curves):
                touch = touch.with_context(context)
            elif touch.outliers:               # a slipping sensor: its curves' ends judged by the fit
                return judge_ends(touch, search, refit, self._residuals, self.estimation)
            return touch, search(touch)

        touch, outcome = searched(data, budget)
        if data.contact is None and not self._fits(touch, outcome) and missing(touch):
            touch, outcome = other_meetings(data, touch, outcome, searched, self._fits, budget)
        return self._recognition(touch, outcome, start)

    def _contacts(self, data: TactileData, chosen) -> tuple[Touch, SearchOutcome]:
        """A touch of contacts searched over the models ``chosen`` (None: all) by
        :func:`tactrec.engine.contacts.contact_stage`; an :class:`InputError` where they cannot be posed
        (:func:`tactrec.io.contacts.spread_problem`)."""
        from ..engine.contacts import contact_stage
        from ..io.contacts import spread_problem

        problem = spread_problem(data.contacts)
        if problem is not None:
            raise InputError(problem, data.source)
        touch = Touch.from_data(data)
        indices = range(len(self.models)) if chosen is None else chosen
        within = float(getattr(self.config, "within", 3.0))
        fit = fit_limit(touch, self.floor)
        limit = plausible_fit(fit, touch.noise, len(touch.points), within)
        found = dict(zip(indices, self.runner.map(contact_stage, list(indices), touch, limit, fit)))
        ranking = [found.get(i) or Registration(e.name, np.inf, outcome=Outcome.NOT_SEARCHED,
                                                reason=NOT_SEARCHED)
                   for i, e in enumerate(self.models)]
        return touch, SearchOutcome(ranking, True, 0, 1, None)

    def unposed(self, touch: Touch, reason: str) -> Recognition:
        """The recognition of a touch no model was searched for, every model not searched for ``reason``
        (a session's contacts before they can be posed)."""
        ranking = [Registration(e.name, np.inf, outcome=Outcome.NOT_SEARCHED, reason=reason) for e in self.models]
        return self._recognition(touch, SearchOutcome(ranking, True, 0, 0, None), time.perf_counter())

    def _recognition(self, touch: Touch, outcome, start: float) -> Recognition:
        """The :class:`~.result.Recognition` of ``outcome``, the search of ``touch``: the ranking by error,
        the evidence of the probabilities (computed now: they are part of its seconds)."""
        ranking = sorted(outcome.ranking, key=_rank_key)
        ok = [r for r in ranking if r.ok]
        limit = max(fit_limit(touch, self.floor), touch.fit)
        found = evidence([r.model for r in ok], self._residuals_of(ok, touch),
                         [len(c) for c in touch.joint_curves], touch.noise, limits=(limit,),
                         resolution=resolution(touch, self.floor), radii=(touch.radius,),
                         tied=self._tied(ok, touch, limit, outcome.settled), kind=touch.data.kind)
        out = Recognition(ranking, touch.estimate, 0.0, self.method.name, found, outcome.settled, outcome.work,
                          outcome.depth, touch, outcome.allowed, self.unknown_prior, self.chance)
        out.best                                # the answer and its probabilities are part of its seconds
        others = other_places(out.registration, touch)
        if others:                              # whether the data tell its place from the others posed there
            answer = self._residuals_of([out.registration], touch)
            share = place_share(answer + self._residuals_of(others, touch), touch, self.floor)
            if share >= AMBIGUOUS:              # the polish brings the others' fits closer: only then can it tell
                polished = self.runner.map(place_stage, [self._number[r.model] for r in others], touch, items=others)
                share = place_share(answer + polished, touch, self.floor)
            object.__setattr__(out, "place", share)                               # set once, before anyone sees it
        object.__setattr__(out, "seconds", time.perf_counter() - start)          # set once, before anyone sees it
        return out

    def _tied(self, ok: list[Registration], touch: Touch, limit: float, settled: bool) -> int:
        """How many of the registrations ``ok`` (best first) the probabilities read as the best's fit
        (:attr:`~tactrec.probability.Evidence.tied`): where the search did not settle and its best is
        beyond a plausible fit (:func:`~tactrec.probability.plausible_fit`), its errors only bound each
        model's fit, and those within the method's ``ratio`` of the best (or of ``limit``), which its
        next round would have searched, are not told apart; 1 otherwise, or where the method has no
        such ratio."""
        ratio, within = getattr(self.config, "ratio", None), getattr(self.config, "within", None)
        if settled or ratio is None or within is None or not ok:
            return 1
        best = ok[0].error / ok[0].scale
        if best <= plausible_fit(limit, touch.noise, len(touch.joint_points), float(within)):
            return 1
        bound = float(ratio) * max(best, limit)
        return int(sum(r.error / r.scale <= bound for r in ok))

    def _fits(self, touch: Touch, outcome) -> bool:
        """Whether the best registration of ``outcome`` fits ``touch`` (within its fit limit)."""
        return best_error(outcome) <= max(fit_limit(touch, self.floor), touch.fit)

    @property
    def floor(self) -> float:
        """The method's ``floor`` (a fit's mean distance per unit radius on noise-free data), or
        :data:`FLOOR` for a method without one."""
        return float(getattr(self.config, "floor", FLOOR))

    def _residuals_of(self, found: list[Registration], touch: Touch) -> list[np.ndarray]:
        """The data's signed distances (data units) to the model of each registration of ``found``
        under its pose (to the model offset by each point's tip: :mod:`tactrec.tip`), computed where
        the models are held (:func:`residual_stage`)."""
        return self.runner.map(residual_stage, [self._number[r.model] for r in found], touch, items=found)

    def _residuals(self, r: Registration, touch: Touch) -> np.ndarray:
        return self._residuals_of([r], touch)[0]


def residual_stage(held, indices, touch: Touch, found: list[Registration]) -> list[np.ndarray]:
    """A runner's stage: :meth:`Recognizer._residuals_of` for the models ``indices`` of ``held``."""
    return [residuals(touch.in_units(r.scale).exact(held.entries[i].model), r.rotation, r.translation,
                      touch.joint_points, r.scale) for i, r in zip(indices, found)]


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
