"""Several touches of one still object: one pose per model that fits them all.

A :class:`Session` keeps the touches of one object in a common *world*
frame, one :class:`~.record.TouchRecord` per touch.  Adding a touch
(:meth:`Session.add`) costs one recognition of that touch and a joint
refinement (more searches only in step 5):

1. the touch, moved into the world frame by its ``sensor2world`` pose, is
   recognised on its own by the recognizer's method; each accepted model's
   registration is then a world-to-model pose;
2. for every model, the candidate poses are its joint pose so far (with the
   poses along its free motions, where they were computed) and the new
   touch's poses on it (the best and the others its search refined); each is
   scored on all touches' points, and the best two are refined jointly
   (point-to-plane Gauss-Newton on every point of every touch kept;
   :mod:`.fit`, in the recognizer's worker processes); within one add, a model is fitted again
   after the search of step 5 only from its fit and that search's poses;
3. a touch is *consistent* with a pose when its mean distance under it is
   within three standard errors of its own fit on that model, or of the
   largest mean distance still a fit (:func:`tactrec.probability.fit_limit`:
   a perfect fit's under its noise, or the method's ``floor`` x its radius on
   noise-free data), whichever is larger: the noise of that touch decides,
   not a fixed tolerance;
4. a touch that no pose fitting most touches fits is reported as *slipped*
   (the contact moved, or the object did) and left out of every fit and
   probability, never averaged in;
5. when the best model's pose is not consistent with every touch not set
   aside before this one (the new touch and any step 4 now calls slipped
   included: a pose the earlier search missed can make a good touch look
   slipped), or is consistent with them all but not a fit under their
   noise (its mean distance beyond the fit test's allowance over the
   points-weighted mean of their ``fit_limit``: another pose may fit them
   better), the new touch is searched again with every touch kept in its
   score (:meth:`tactrec.recognition.Recognizer.recognize` with
   ``context``), and steps 2-4 run again on its poses; if still no pose fits
   them all at their noise, the touch kept before it is searched the same
   way with the others in its score (:data:`STARTS`).  Once the best pose
   does fit them all at their noise, a second pass from the same starts
   searches its rivals: the models every touch fits on its own whose joint
   pose does not fit them all at their noise (a search of the first pass
   stops once the best model fits, before it reaches a rival's pose).  That
   pose may be one the joint fit missed (each touch's own poses on the model
   place the others wrongly), and a model is never counted out on a joint
   pose no search looked for.  Each search is the
   engine's (:mod:`tactrec.engine`): every place of each model at every
   rotation, screened with one point of each other touch's curves in the
   score, so it costs about what the touch's own search costs, whatever the
   number of touches, and reaches places the touch's curvature ranks last.
   But it poses the data from its start's normal, and a short noisy
   touch's normal can be too far off for the screen to reach the truth from
   it, where another touch's is not: so two starts, not one, and not every
   touch (each search scores all the touches, and the cost of an add would
   grow with the square of their number).  The searches cover the models
   the new touch fits on its own (its own search's error as good as its
   best model's, or as ``fit_limit``, by the one fit test,
   :func:`~.record.fits`) whose pose does not fit every touch (every such
   model when the best pose fits them all, but not at their noise): a model
   the touch does not fit cannot fit it jointly.  When the new touch's own
   search fitted no model, its errors rule nothing out and every model
   whose pose does not fit every touch is covered.  A search of the first
   pass stops once its best pose fits the touches as well as their own
   searches fit each (the points-weighted mean of each touch's best fit on
   any model, or of ``fit_limit``, whichever is larger); one of the
   rivals' pass once a rival fits them as well as the best's joint pose
   does (or its start touch's own ``fit_limit``, where that is larger).
   Each pass's searches share one budget, the work (closest-point queries)
   the touch's own search spent, times ``search_budget``: each is given
   what is left (its first round whatever it costs), and none starts once
   it is spent.  A method that counts no work has no budget, and one that
   scores no other touches' points (the paper's) searches no more than
   step 1;
6. the probabilities (:mod:`tactrec.probability`) come from every model's
   distances to the points of all touches kept, under its joint pose, and
   from the lines the sensor followed without meeting anything
   (:meth:`Session.add_miss`, :mod:`.lines`).

Touches of round tips (:mod:`tactrec.tip`), of one radius or several: each
touch's distances are measured against the model offset by its own tip; step
5 screens the other touches moved onto the surface (by their own estimates).
A missed line is measured against the model itself (:mod:`.lines`).
"""

from __future__ import annotations

import dataclasses
import functools
import time

import numpy as np

from ..errors import InputError
from ..io.session import SessionTouch, rigid_pose
from ..io.touch import TactileData
from ..probability import evidence, fit_limit, residuals, resolution
from ..recognition import FLOOR
from .fit import joint_model
from .joint import JointFit
from .lines import miss_excess
from .record import TouchRecord, allowed_fit, fits
from .result import Hypothesis, SessionResult

__all__ = ["Session", "STAGES", "FLOOR", "STARTS"]

#: step 5 searches from this many touches, newest first: the new one and the one kept before it (a
#: noisy touch's normal may be too far off for the screen to pose the truth from it; another
#: touch's may not), so a touch may be searched from when it is added and when the next one is
STARTS = 2
#: the parts of an add whose seconds :attr:`SessionResult.stages` gives: the touch's own search
#: (step 1), the joint fits (steps 2-4 and 6, each time they run) and the search with the other
#: touches in the score (step 5)
STAGES = ("own", "joint", "context")


def _atomic(method):
    """``method`` leaves the session as it was when it raises (a bad touch, an interrupted search)."""
    @functools.wraps(method)
    def run(self, *args, **kwargs):
        state = dict(vars(self), records=list(self.records), misses=list(self.misses), _joint=dict(self._joint))
        try:
            return method(self, *args, **kwargs)
        except BaseException:
            vars(self).update(state)
            raise
    return run


class Session(JointFit):
    """Touches of one still object, recognised together (see the module text).

    Parameters
    ----------
    recognizer : tactrec.recognition.Recognizer
        Holds the models and the method; it is kept between touches (nothing is rebuilt).
    joint_search : bool
        When the best model's pose does not fit every touch, search the new touch again with the
        other touches' points in the score (step 5 of the module text, for a method that scores
        a context); False keeps to step 1.
    search_budget : float or None
        Step 5's budget per pass, in multiples of the work the touch's own search spent (1: an add
        costs at most about three times the touch alone, twice where no rival is left to search);
        None gives the search the method's own budget.
    """

    def __init__(self, recognizer, *, joint_search: bool = True, search_budget: float | None = 1.0):
        if search_budget is not None and not (np.isfinite(search_budget) and search_budget >= 0):
            raise ValueError(f"search_budget must be a non-negative number or None, not {search_budget!r}")
        self.joint_search = joint_search
        self.search_budget = search_budget
        self.recognizer = recognizer
        self.records: list[TouchRecord] = []
        self.misses: list = []                 # lines that met nothing, world frame
        self.searches: list = []               # this add's recognitions: where new candidate poses come from
        self._joint: dict[str, Hypothesis] = {}
        self._fits: dict[bytes, dict[str, Hypothesis]] = {}   # this add's fits, per set of touches used
        self.result: SessionResult | None = None
        self._stages: dict[str, float] = {}     # this add's seconds per stage

    @property
    def features(self) -> list:
        """Each touch's :class:`~tactrec.features.Touch` (world frame), in order."""
        return [r.features for r in self.records]

    @property
    def tips(self) -> np.ndarray:
        """Each touch's tip radius ``(N,)``, data units."""
        return np.array([r.tip for r in self.records], dtype=np.float64)

    @property
    def world(self) -> list:
        """Each touch's data in the world frame, in order."""
        return [r.world for r in self.records]

    def contacts(self) -> np.ndarray:
        """Each touch's contact in the world frame ``(N, 3)``: the one its data give, else its estimate's."""
        return np.array([r.world.contact if r.world.contact is not None else r.features.geometry.contact
                         for r in self.records])

    @_atomic
    def add(self, data: TactileData, sensor2world=None) -> SessionResult:
        """Add a touch (sensor frame; ``sensor2world`` a ``(rotation, translation)`` pair or None for
        points already in the world frame) and recognise the session again; where it raises, the
        session is as it was."""
        start = time.perf_counter()
        if sensor2world is None:
            touch = SessionTouch(data)
        else:
            touch = SessionTouch(data, *rigid_pose(*sensor2world, data.source))
        if self.records and data.units != self.records[0].given.data.units:
            raise InputError(f"this touch is in {data.units!r}, the session in {self.records[0].given.data.units!r}",
                             data.source)
        world = touch.in_world()
        slipped = set(self.result.slipped) if self.result is not None else set()
        earlier = any(i not in slipped for i in range(len(self.records)))
        self._stages = dict.fromkeys(STAGES, 0.0)
        own = self._timed("own", self.recognizer.recognize, world)
        self.records.append(TouchRecord(touch, world, own))
        self.searches = [own]
        self._fits = {}
        self.result = self._joint_fit()
        if self.joint_search and earlier and self.recognizer.method.scores_context:
            self._search_jointly(slipped, own.work)
        self.result = dataclasses.replace(self.result, seconds=time.perf_counter() - start, stages=self._stages)
        return self.result

    @_atomic
    def add_miss(self, line, sensor2world=None) -> SessionResult | None:
        """Add a touch whose approach ``line`` (:class:`~tactrec.io.session.MissedLine`, sensor frame;
        ``sensor2world`` as for :meth:`add`) met nothing: evidence against every pose whose surface
        it cuts (:mod:`.lines`).  The result (None before any touch met the object) is the last one's
        with the probabilities weighed again; nothing is searched."""
        start = time.perf_counter()
        if sensor2world is not None:
            line = line.transformed(*rigid_pose(*sensor2world, "missed line"))
        self.misses.append(line)
        if self.result is None:
            return None
        kept = self.kept()
        self.result = dataclasses.replace(self.result, evidence=self._evidence(self.result.ranking, kept),
                                          missed=len(self.misses), seconds=time.perf_counter() - start,
                                          stages=dict.fromkeys(STAGES, 0.0))
        return self.result

    def _evidence(self, ranked, keep):
        """The :class:`~tactrec.probability.Evidence` of the hypotheses ``ranked`` over the touches
        ``keep`` (indices) and the missed lines (None without a hypothesis or a touch)."""
        if not ranked or not keep:
            return None
        by_name = {e.name: e.model for e in self.recognizer.models}
        x = np.concatenate([self.records[i].points for i in keep])
        curves = [len(c) for i in keep for c in self.features[i].curves]
        points, use = [r.points for r in self.records], np.isin(np.arange(len(self.records)), keep)
        signed = [residuals(joint_model(by_name[h.model], points, self.tips, h.scale, use), h.rotation,
                            h.translation, x, h.scale) for h in ranked]
        misses = None
        if self.misses:
            step = 0.5 * float(np.median([self.records[i].world.spacing for i in keep]))
            misses = miss_excess(by_name, ranked, self.misses, step=step, limit=self.limit(keep))
        return evidence([h.model for h in ranked], signed, curves, float(np.median([f.noise for f in self.features])),
                        limits=[fit_limit(self.features[i], self.floor) for i in keep],
                        touches=[len(self.features[i].curves) for i in keep], misses=misses,
                        resolution=min(resolution(self.features[i], self.floor) for i in keep),
                        radii=[self.features[i].radius for i in keep])

    def _timed(self, stage: str, fn, *args, **kwargs):
        """``fn(*args, **kwargs)``, its seconds added to this add's ``stage`` (:data:`STAGES`)."""
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            self._stages[stage] += time.perf_counter() - start

    def _search_jointly(self, slipped: set, work: int) -> None:
        """Step 5, in two passes over the same starts, the new touch then the one kept before it
        (:data:`STARTS`), each search with every other touch kept in the score: while no pose found
        fits every touch kept at their noise, over the models the new touch fits on its own whose
        pose does not fit them all (every such model once the best pose fits them all but not at
        their noise); then, once the best pose fits them at their noise, over its rivals
        (:meth:`_rivals`).  A search of the first pass stops once a pose fits the touches as well
        as their own searches fit each, so it may stop on the best model before it reached a
        rival's pose: the second looks for the rivals' own, and stops once a pose of one fits as
        well as the best's (or the start touch's own fit limit, where that is larger).  Each pass
        has its budget, ``work`` (what the touch's own search spent) x ``search_budget``, shared by
        its searches: a rival is searched even where finding the best took the first pass's."""
        use = [i for i in range(len(self.records)) if i not in slipped]
        fit = self.pooled(self._reference()[use], use)
        starts = use[::-1][:STARTS]
        for rivals in (False, True):
            budget = np.inf if self.search_budget is None or work <= 0 else self.search_budget * work
            for start in starts:
                explained = self._explained(slipped)
                if budget <= 0:
                    break
                if explained and self._fitted():
                    among = self._rivals(use) if rivals else []
                elif rivals:
                    return                                    # the best pose itself was not found
                else:
                    among = self._unexplained(slipped, every=explained)
                if not among:
                    break
                # a rival is level once a pose of it fits as well as the best's does
                goal = min(fit, self.result.ranking[0].error) if rivals else fit
                budget -= self._search_from(start, use, among, goal, budget)

    def _search_from(self, start: int, use: list[int], among: list[str], fit: float, budget: float) -> int:
        """One search of step 5: touch ``start`` searched again over the models ``among`` with the
        other touches ``use`` in its score, until a pose fits them as well as ``fit`` or ``budget``
        is spent; the joint fit is made again on its poses.  Returns the work it spent."""
        others = [self.records[i] for i in use if i != start]
        context = [c for r in others for c in r.features.data.curves]          # the points each kept
        tips = [r.tip for r in others for _ in r.features.data.curves]
        surface = [c for r in others for c in r.surface_curves]
        kept = self.records[start].features.data
        found = self._timed("context", self.recognizer.recognize, kept, context=context,
                            among=among, fit=fit, budget=None if np.isinf(budget) else int(budget),
                            context_tips=tips, context_surface=surface)
        self.searches.append(found)
        self.result = self._joint_fit(found)
        return found.work

    def kept(self) -> list[int]:
        """The touches the session's result uses: all but those it calls slipped."""
        slipped = () if self.result is None else self.result.slipped
        return [i for i in range(len(self.records)) if i not in slipped]

    def _points(self, touches) -> np.ndarray:
        """How many points each of the touches ``touches`` (indices) has: ``(k,)``."""
        return np.array([len(self.records[i].points) for i in touches], dtype=np.float64)

    def pooled(self, values, touches) -> float:
        """The points-weighted mean of per-touch ``values`` (one per index of ``touches``)."""
        sizes = self._points(touches)
        return float((sizes * np.asarray(values, dtype=np.float64)).sum() / sizes.sum())   # element-wise: no BLAS

    def fitted_at(self, error: float, touches) -> bool:
        """Whether a pose whose points-weighted mean distance over the touches ``touches`` (indices)
        is ``error`` (data units) fits them as well as their noise allows (the points-weighted mean
        of their :func:`fit_limit`, by the one fit test :func:`~.record.fits`): then no search can
        fit them better."""
        return bool(fits(error, self.limit(touches), self._points(touches).sum()))

    def limit(self, touches) -> float:
        """The points-weighted mean of the :func:`fit_limit` of the touches ``touches`` (indices)."""
        return self.pooled([fit_limit(self.records[i].features, self.floor) for i in touches], touches)

    def _explained(self, slipped: set) -> bool:
        """Whether the best model's joint pose is consistent with every touch but those ``slipped``
        before this one, the new touch included even if step 4 calls it slipped: a touch is only
        left out as slipped once the search scoring its poses on every touch (step 5) has found
        none that fits them all."""
        best = self.result.ranking[0] if self.result.ranking else None              # the best fit
        return best is not None and all(c for i, c in enumerate(best.consistent) if i not in slipped)

    @property
    def floor(self) -> float:
        """The method's ``floor`` (a fit's mean distance per unit radius on noise-free data), or :data:`FLOOR`."""
        return self.recognizer.floor

    def _reference(self, model: str | None = None) -> np.ndarray:
        """Per touch ``(N,)``, data units: the fit its own search reached on ``model`` (None: on its
        best model), or :func:`fit_limit`, whichever is larger: what the fit test measures it against."""
        return np.array([max(r.own_error(model), fit_limit(r.features, self.floor)) for r in self.records])

    def _limits(self) -> np.ndarray:
        """Per touch ``(N,)``, data units: the largest mean distance of a fit as good as its own search
        found on any model (:func:`~.record.allowed_fit` of :meth:`_reference`)."""
        return allowed_fit(self._reference(), self._points(range(len(self.records))))

    def _fitted(self) -> bool:
        """Whether the best model's joint pose fits the touches kept as well as their noise allows
        (:meth:`fitted_at`): then no search can fit them better."""
        return bool(self.result.ranking) and self.fitted_at(self.result.ranking[0].error, self.kept())

    def _unexplained(self, slipped: set, *, every: bool = False) -> list[str]:
        """The models step 5 searches: those whose joint pose is not consistent with every touch but
        those ``slipped`` before (``every``: whether or not it is, for a best pose consistent with
        every touch but not a fit under their noise, which another pose may beat), and that the new
        touch fits on its own (its own search's error within :meth:`_limits`).  When that search
        fitted no model (its best error not as good as :func:`fit_limit`, by the fit test), its
        errors rule nothing out: every such model is searched, those it deferred unrefined
        included."""
        new = self.records[-1]
        fitted = fits(self._reference()[-1], fit_limit(new.features, self.floor), len(new.points))
        limit = self._limits()[-1] if fitted else np.inf
        out = []
        for r in new.own.ranking:
            h = self.result.hypothesis(r.model)
            fits_all = h is not None and all(c for i, c in enumerate(h.consistent) if i not in slipped)
            own = r.error / r.scale if r.ok else (np.inf if r.deferred else None)
            if own is not None and own <= limit and (every or not fits_all):
                out.append(r.model)
        return out

    def _rivals(self, use: list[int]) -> list[str]:
        """The models step 5 searches once the best pose fits every touch at their noise: those every
        touch ``use`` (indices) fits on its own (its own search's error within :meth:`_limits`) whose
        joint pose does not fit them all at their noise (:meth:`fitted_at`), as the best's does.
        Such a joint pose may be one the search missed, and a model is never counted out on a pose
        no search looked for: a worse joint fit is evidence only once the search has looked."""
        limits = self._limits()
        own = [{r.model: r.error / r.scale for r in self.records[i].own.ranking if r.ok} for i in use]
        best = self.result.ranking[0].model
        out = []
        for h in self.result.ranking:
            if h.model == best or (all(h.consistent[i] for i in use) and self.fitted_at(h.error, use)):
                continue
            if all(h.model in errors and errors[h.model] <= limits[i] for i, errors in zip(use, own)):
                out.append(h.model)
        return out

    def next(self, *, radius: float, angle: float = 60.0, candidates: int | None = None, rng=None):
        """Where to touch next: an approach line and the curves to trace (:func:`tactrec.proposal.propose`;
        ``candidates`` None: its :data:`~tactrec.proposal.CANDIDATES`)."""
        from ..proposal import CANDIDATES, propose

        return propose(self, radius=radius, angle=angle, candidates=candidates or CANDIDATES, rng=rng)
