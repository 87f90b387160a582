"""Several touches of one still object: one pose per model that fits them all.

A :class:`Session` keeps the touches of one object in a common *world*
frame.  Adding a touch (:meth:`Session.add`) costs one recognition of that
touch and a joint refinement (more searches only in step 5):

1. the touch, moved into the world frame by its ``sensor2world`` pose, is
   recognised on its own by the recognizer's method; each accepted model's
   registration is then a world-to-model pose;
2. for every model, the candidate poses are its joint pose so far (with the
   poses along its free motions, where they were computed) and the new
   touch's poses on it (the best and the others its search refined); each is
   scored on all touches' points, and the best two are refined jointly
   (point-to-plane Gauss-Newton on every point of every touch kept;
   :mod:`tactrec.session_fit`, in the recognizer's worker processes); within one add, a model is fitted again
   after a search of step 5 only from its fit and that search's poses;
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
   included: a pose the earlier searches missed can make a good touch look
   slipped), the new touch is searched again with the earlier touches'
   points in the score (:meth:`tactrec.recognition.Recognizer.recognize`
   with ``context``), and steps 2-4 run again on its poses; if still no pose
   fits them all, the touch kept before it is searched the same way with the
   others as its context (:data:`STARTS`): a touch may be searched with the
   others in its score when it is added and again when the next one is.  A
   search ranks a touch's places by curvature, and on a short noisy touch
   the true place can rank beyond its schedule; another touch's places rank
   by other curvatures.  A touch's search is not repeated from every earlier
   touch: each such search scores all the touches, and the cost of an add
   would grow with the square of their number.  Those searches cover the
   models the new touch fits on its own (its own search's error within three
   standard errors of its best model's, or of ``fit_limit``) whose pose does
   not fit every touch: a model the touch does not fit cannot fit it
   jointly, and one whose pose fits them all needs no other.  When the new
   touch's own search fitted no model (its best error beyond ``fit_limit``
   and three standard errors), its errors rule nothing out and every model
   whose pose does not fit every touch is covered.  Each search may try as
   many poses per model as the touch's own search (within the budget below),
   each scored on every touch (the first screen, which every pose takes, on
   one point of each other curve: about the cost of the touch's own screen,
   :meth:`tactrec.features.Touch.screen_subset`), and it stops once its best
   pose fits the touches as well as their own searches fit each (the
   points-weighted mean of each touch's best fit on any model, or of
   ``fit_limit``, whichever is larger): the joint form of the single
   search's rule, with no allowance above it, since a search that stops at a
   pose a little off hands the lead to another model.  Then, when the best
   model's joint pose is still not a fit under the touches' noise (its mean
   distance beyond three standard errors of the points-weighted mean of
   their :func:`~tactrec.probability.fit_limit`), the *pair search*
   (:mod:`tactrec.session_pairs`) poses the models from the new touch and
   the kept touch farthest from it, over every place of a model and with no
   curvature ranking, and steps 2-4 run again on its poses.  It takes the
   models a few at a time, the best joint fits first, and stops once one of
   its poses fits the touches at their noise: the rule that starts it ends
   it, and a search that found the leader's true pose among the first models
   does not pose the rest.  Step 5's searches share one *budget*, the work
   (closest-point queries) the touch's own search spent in step 1: each
   search is given what is left (the searches with the other touches in the
   score stop before a round of candidates that would exceed it, their first
   round whatever it costs; the pair search stops after the batch of models
   that spends it), and none starts once it is spent.  An add then costs
   about twice the touch's own search and the joint fits, whatever the
   number of models; a pose the budget left unfound may be found when the
   next touch is added, whose step 5 searches again.  A method that counts
   no work (the paper's) has no budget;
6. the probabilities (:mod:`tactrec.probability`) come from every model's
   distances to the points of all touches kept, under its joint pose.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from .errors import InputError
from .io.session import SessionTouch, rigid_pose
from .io.touch import TactileData
from .linalg import clearly_less
from .probability import evidence, fit_limit, fit_standard_error, residuals
from . import session_family, session_pairs
from .session_fit import fit_stage
from .session_result import Hypothesis, SessionResult


__all__ = ["Session", "SessionResult", "Hypothesis", "CONSISTENT_SE", "STAGES", "allowed_fit"]

#: a touch is consistent with a pose when its mean distance is within this many standard errors of its own fit
CONSISTENT_SE = 3.0
#: on noise-free data a fit is within this fraction of the touch's radius, for a method without a ``floor`` of its own
FLOOR = 1e-3
#: step 5 searches from this many touches, newest first: the new one and the one kept before it, so a
#: touch may be searched with the others in its score when it is added and again when the next one is
STARTS = 2
#: the parts of an add whose seconds :attr:`SessionResult.stages` gives: the touch's own search
#: (step 1), the joint fits (steps 2-4 and 6, each time they run), the searches with the other
#: touches in the score and the pair search (step 5)
STAGES = ("own", "joint", "context", "pairs")


def allowed_fit(fit: float, points: int) -> float:
    """The largest mean distance as good as a fit of ``fit`` over ``points`` points: within
    :data:`CONSISTENT_SE` of its standard errors."""
    return fit + CONSISTENT_SE * fit_standard_error(fit, points)


class Session:
    """Touches of one still object, recognised together (see the module text).

    Parameters
    ----------
    recognizer : tactrec.recognition.Recognizer
        Holds the models and the method; it is kept between touches (nothing is rebuilt).
    joint_search : bool
        When the best model's pose does not fit every touch, search the new touch again with the
        earlier touches' points in the score (step 5 of the module text, for a method that scores
        a context); False keeps to step 1.
    search_budget : float or None
        Step 5's budget, in multiples of the work the touch's own search spent (1: an add costs
        about twice the touch alone); None searches without one, each search to its own budget
        and the pair search through every model while no pose fits.
    """

    def __init__(self, recognizer, *, joint_search: bool = True, search_budget: float | None = 1.0):
        if search_budget is not None and not (np.isfinite(search_budget) and search_budget >= 0):
            raise ValueError(f"search_budget must be a non-negative number or None, not {search_budget!r}")
        self.joint_search = joint_search
        self.search_budget = search_budget
        self.searches: list = []               # this touch's recognitions: where new candidate poses come from
        self.recognizer = recognizer
        self.touches: list[SessionTouch] = []
        self.world: list[TactileData] = []
        self.solo: list = []                   # each touch's own Recognition (world frame)
        self.features: list = []
        self._joint: dict[str, Hypothesis] = {}
        self._fits: dict[bytes, dict[str, Hypothesis]] = {}   # this add's fits, per set of touches used
        self.result: SessionResult | None = None
        self._stages: dict[str, float] = {}     # this add's seconds per stage

    def add(self, data: TactileData, sensor2world=None) -> SessionResult:
        """Add a touch (sensor frame; ``sensor2world`` a ``(rotation, translation)`` pair or None for
        points already in the world frame) and recognise the session again."""
        start = time.perf_counter()
        if sensor2world is None:
            touch = SessionTouch(data)
        else:
            touch = SessionTouch(data, *rigid_pose(*sensor2world, data.source))
        if self.touches and data.units != self.touches[0].data.units:
            raise InputError(f"this touch is in {data.units!r}, the session in {self.touches[0].data.units!r}",
                             data.source)
        world = touch.in_world()
        slipped = set(self.result.slipped) if self.result is not None else set()
        earlier = any(i not in slipped for i in range(len(self.world)))
        self._stages = dict.fromkeys(STAGES, 0.0)
        rec = self._timed("own", self.recognizer.recognize, world)
        self.touches.append(touch)
        self.world.append(world)
        self.solo.append(rec)
        self.searches = [rec]
        self.features.append(rec.touch)
        self._fits = {}
        self.result = self._joint_fit()
        if self.joint_search and earlier:
            # step 5's searches share the work the touch's own search spent (a method that counts
            # none has no budget): those from one touch with the others in the score, then the pair
            # search while no pose fits the touches at their noise
            budget = np.inf if self.search_budget is None or rec.work <= 0 else self.search_budget * rec.work
            if self.recognizer.method.scores_context:
                budget = self._search_jointly(slipped, budget)
            if not self._fitted() and budget > 0:
                found = self._timed("pairs", session_pairs.search, self,
                                    [i for i in range(len(self.features)) if i not in slipped], budget=budget)
                if found is not None:
                    self.searches.append(found)
                    self.result = self._joint_fit(found)
        self.result = dataclasses.replace(self.result, seconds=time.perf_counter() - start, stages=self._stages)
        return self.result

    def _timed(self, stage: str, fn, *args, **kwargs):
        """``fn(*args, **kwargs)``, its seconds added to this add's ``stage`` (:data:`STAGES`)."""
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            self._stages[stage] += time.perf_counter() - start

    def _search_jointly(self, slipped: set, budget: float) -> float:
        """Step 5: while no pose found fits every touch kept, search again from one of them, scoring
        poses on all: the new touch, then the one kept before it (:data:`STARTS`).  Each search covers
        the models the new touch fits on its own whose pose does not fit them all, and stops once a
        pose fits the touches as well as their own searches fit each.  ``budget``: the work step 5
        may still spend (each search is given it); returns what is left."""
        use = [i for i in range(len(self.features)) if i not in slipped]
        fit = self.pooled(self._own_fits()[use], use)
        for start in use[::-1][:STARTS]:
            if self._explained(slipped) or budget <= 0:
                return budget
            among = self._unexplained(slipped)
            if not among:
                return budget
            # a search that stopped at a pose the other touches rule out may reach the truth from
            # another touch, whose places rank by other curvatures
            context = [c for i in use if i != start for c in self.world[i].curves]
            found = self._timed("context", self.recognizer.recognize, self.world[start], context=context,
                                among=among, fit=fit, budget=None if np.isinf(budget) else int(budget))
            budget -= found.work
            self.searches.append(found)
            self.result = self._joint_fit(found)
        return budget

    def kept(self) -> list[int]:
        """The touches the session's result uses: all but those it calls slipped."""
        slipped = () if self.result is None else self.result.slipped
        return [i for i in range(len(self.features)) if i not in slipped]

    def pooled(self, values, touches) -> float:
        """The points-weighted mean of per-touch ``values`` (one per index of ``touches``)."""
        sizes = np.array([len(self.features[i].points) for i in touches], dtype=np.float64)
        return float((sizes * np.asarray(values, dtype=np.float64)).sum() / sizes.sum())   # element-wise: no BLAS

    def allowed(self, fit: float, touches) -> float:
        """The largest points-weighted mean distance over the touches ``touches`` (indices) as good
        as a fit of ``fit``: within :data:`CONSISTENT_SE` standard errors over their points."""
        return allowed_fit(fit, sum(len(self.features[i].points) for i in touches))

    def _fitted(self) -> bool:
        """Whether the best model's joint pose fits the touches kept as well as their noise allows
        (its mean distance within three standard errors of the points-weighted mean of their
        :func:`fit_limit`): then no search can fit them better."""
        return bool(self.result.ranking) and self.fitted_at(self.result.ranking[0].error, self.kept())

    def fitted_at(self, error: float, touches) -> bool:
        """Whether a pose whose points-weighted mean distance over the touches ``touches`` (indices)
        is ``error`` (data units) fits them as well as their noise allows (:meth:`_fitted`)."""
        return error <= self.allowed(self.limit(touches), touches)

    def limit(self, touches) -> float:
        """The points-weighted mean of the :func:`fit_limit` of the touches ``touches`` (indices)."""
        return self.pooled([fit_limit(self.features[i], self.floor) for i in touches], touches)

    def _explained(self, slipped: set) -> bool:
        """Whether the best model's joint pose is consistent with every touch but those ``slipped``
        before this one, the new touch included even if step 4 calls it slipped: a touch is only
        left out as slipped once a search scoring its poses on every touch (step 5) has found none
        that fits them all."""
        best = self.result.hypothesis(self.result.best) if self.result.best else None
        return best is not None and all(c for i, c in enumerate(best.consistent) if i not in slipped)

    @property
    def floor(self) -> float:
        """The method's ``floor`` (a fit's mean distance per unit radius on noise-free data), or :data:`FLOOR`."""
        return getattr(self.recognizer.config, "floor", FLOOR)

    def _own_fits(self) -> np.ndarray:
        """Per touch ``(N,)``, data units: the fit its own search reached on its best model, or
        :func:`fit_limit`, whichever is larger."""
        return np.array([max(min([r.error / r.scale for r in rec.ranking if r.ok], default=0.0),
                             fit_limit(f, self.floor)) for f, rec in zip(self.features, self.solo)])

    def _limits(self) -> np.ndarray:
        """Per touch ``(N,)``, data units: the largest mean distance of a fit as good as its own search
        found on any model: within three standard errors of :meth:`_own_fits`."""
        return np.array([allowed_fit(e, len(f.points)) for e, f in zip(self._own_fits(), self.features)])

    def _unexplained(self, slipped: set) -> list[str]:
        """The models step 5 searches again: those whose joint pose is not consistent with every
        touch but those ``slipped`` before, and that the new touch fits on its own (its own search's
        error within :meth:`_limits`).  When that search fitted no model (its best error beyond
        what the touch's noise allows, :func:`fit_limit` and three standard errors), its errors
        rule nothing out: every model whose joint pose fails some touch is searched, those it
        deferred unrefined included."""
        f = self.features[-1]
        fitted = self._own_fits()[-1] <= allowed_fit(fit_limit(f, self.floor), len(f.points))
        limit = self._limits()[-1] if fitted else np.inf
        out = []
        for r in self.solo[-1].ranking:
            h = self.result.hypothesis(r.model)
            fits_all = h is not None and all(c for i, c in enumerate(h.consistent) if i not in slipped)
            own = r.error / r.scale if r.ok else (np.inf if r.deferred else None)
            if own is not None and own <= limit and not fits_all:
                out.append(r.model)
        return out

    def next(self, *, radius: float, tolerance: float = 1.0, angle: float = 60.0, candidates: int = 48, rng=None):
        """Where to touch next (:func:`tactrec.proposal.propose`)."""
        from .proposal import propose

        return propose(self, radius=radius, tolerance=tolerance, angle=angle, candidates=candidates, rng=rng)

    # -- the joint fit --------------------------------------------------------------------------

    def _candidates(self, name: str, start: Hypothesis | None = None,
                    searches=None) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Model ``name``'s candidate poses ``(R, t, scale)``: ``start``'s pose (default: its joint pose
        so far, with its family where computed), then the poses of ``searches`` (default: this add's)."""
        poses = []
        h = self._joint.get(name) if start is None else start
        if h is not None:
            family = h.poses if h.poses is not None else [np.concatenate([h.rotation, h.translation[:, None]], 1)]
            poses += [(pose[:, :3], pose[:, 3], h.scale) for pose in family]
        for rec in self.searches if searches is None else searches:
            r = next((r for r in rec.ranking if r.model == name and r.ok), None)
            if r is not None:
                poses.append((r.rotation, r.translation, r.scale))
                for alt in (() if r.alternatives is None else r.alternatives):
                    poses.append((alt[:, :3], alt[:, 3], r.scale))
        return poses

    def consistent(self, name: str, per_touch: np.ndarray) -> np.ndarray:
        """Which touches are consistent (module text, step 3) with poses of model ``name`` whose
        per-touch mean distances (data units) are ``per_touch (h, N)``: ``(h, N)`` bool."""
        allowed = []
        for f, rec in zip(self.features, self.solo):
            r = next((r for r in rec.ranking if r.model == name and r.ok), None)
            allowed.append(allowed_fit(max(0.0 if r is None else r.error / r.scale, fit_limit(f, self.floor)),
                                       len(f.points)))
        return per_touch <= np.array(allowed)[None]

    def _fit_models(self, use: np.ndarray, fresh=None) -> dict[str, Hypothesis]:
        """Every model's joint pose on the touches ``use (N,)`` (bool): its candidate poses scored on
        them, the best :data:`~tactrec.session_fit.REFINED` refined on their points
        (:func:`~tactrec.session_fit.fit_stage`, in the recognizer's workers), the best kept.  A model
        already fitted on these touches in this add is fitted again only from that fit and the poses
        of ``fresh`` (the search just made): the other candidates lost to it on the same points."""
        done = self._fits.setdefault(use.tobytes(), {})
        entries, items = [], []
        for i, e in enumerate(self.recognizer.models):
            if e.name in done:
                if fresh is None or not any(r.model == e.name and r.ok for r in fresh.ranking):
                    continue
                poses = self._candidates(e.name, done[e.name], [fresh])
            else:
                poses = self._candidates(e.name)
            if poses:
                entries.append((i, e))
                items.append((np.stack([p[0] for p in poses]), np.stack([p[1] for p in poses]), poses[0][2]))
        weight = np.array([len(f.points) for f in self.features]) * use
        fitted = self.recognizer.runner.map(fit_stage, [i for i, _ in entries], [f.points for f in self.features],
                                            weight, items=items)
        for (_, e), (_, _, scale), poses in zip(entries, items, fitted):
            best = None
            for R, t, per in poses:
                err = float((per * weight).sum() / max(weight.sum(), 1))
                if best is None or clearly_less(err, best.error):
                    best = Hypothesis(e.name, R, t, scale, err, per,
                                      tuple(bool(c) for c in self.consistent(e.name, per[None])[0]))
            done[e.name] = best
        return dict(done)

    def family(self, name: str) -> np.ndarray:
        """Model ``name``'s pose and the poses along the motions its touches leave free, ``(p, 3, 4)``
        (:func:`tactrec.session_family.free_poses`; computed when asked, for the models :meth:`next` weighs)."""
        h = self._joint[name]
        if h.poses is None:
            model = next(e.model for e in self.recognizer.models if e.name == name)
            kept = self.kept()
            use = np.isin(np.arange(len(self.features)), kept)
            x = np.concatenate([self.features[i].points for i in kept]) * h.scale
            h = dataclasses.replace(h, poses=session_family.free_poses(self, model, h, use, x))
            self._joint[name] = h
        return h.poses

    def _joint_fit(self, fresh=None) -> SessionResult:
        """Steps 2-4 and 6, after the search ``fresh`` of step 5 (None: after the touch's own)."""
        return self._timed("joint", self._joint_fit_untimed, fresh)

    def _joint_fit_untimed(self, fresh=None) -> SessionResult:
        n = len(self.features)
        every = np.ones(n, dtype=bool)
        found = self._fit_models(every, fresh)
        # a touch has slipped when no pose that fits most touches fits it; without such a pose
        # the session cannot tell which touch is the odd one out
        majority = [h for h in found.values() if 2 * sum(h.consistent) > n]
        slipped = tuple(i for i in range(n) if not any(h.consistent[i] for h in majority)) if majority else ()
        keep = [i for i in range(n) if i not in slipped]
        if slipped:
            use = np.isin(np.arange(n), keep)
            found = self._fit_models(use, fresh)
        self._joint = found
        by_name = {e.name: e for e in self.recognizer.models}
        ranked = sorted(found.values(), key=lambda h: (h.error, h.model))
        ev = None
        if ranked and keep:
            x = np.concatenate([self.features[i].points for i in keep])
            curves = [len(c) for i in keep for c in self.features[i].curves]
            signed = [residuals(by_name[h.model].model, h.rotation, h.translation, x, h.scale) for h in ranked]
            ev = evidence([h.model for h in ranked], signed, curves, float(np.median([f.noise for f in self.features])))
        rejected = {e.name: "no pose from any touch" for e in self.recognizer.models if e.name not in found}
        return SessionResult(ranked, ev, slipped, n, rejected, 0.0, self.features[-1].geometry)


