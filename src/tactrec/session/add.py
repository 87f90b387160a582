"""One add of a session (:mod:`.core`, steps 1-6): created by :meth:`~.core.Session.add`, dropped after it.

:class:`Add` holds what the add needs while it runs and nothing after: the touches with the new one,
its recognitions, its seconds per stage and its joint fit (:class:`~.joint.JointFit`).  The session
takes the touches, the joint poses and the result from it once the add has run; an add that raises
leaves the session as it was.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..features import Context
from ..probability import fit_limit
from ..registration.result import Outcome
from .joint import JointFit
from .record import TouchRecord, fits
from .touches import Touches

__all__ = ["Add", "STAGES", "STARTS"]

#: step 5 searches from this many touches, newest first: the new one and the one kept before it (a
#: noisy touch's normal may be too far off for the screen to pose the truth from it; another
#: touch's may not), so a touch may be searched from when it is added and when the next one is
STARTS = 2
#: the parts of an add whose seconds :attr:`SessionResult.stages` gives: the touch's own search
#: (step 1), the joint fits (steps 2-4 and 6, each time they run) and the search with the other
#: touches in the score (step 5)
STAGES = ("own", "joint", "context")


class Add:
    """The steps of one add (see the module text and :mod:`.core`).

    Parameters
    ----------
    recognizer : tactrec.recognition.Recognizer
    touches : Touches
        The session's touches before this one.
    misses : sequence of MissedLine
        The lines that met nothing, world frame.
    joint : dict
        Every model's joint pose so far (:class:`~.result.Hypothesis`, by name).
    search_budget : float or None
        Step 5's budget per pass, in multiples of the work the touch's own search spent.
    """

    def __init__(self, recognizer, touches: Touches, misses, joint: dict, *, search_budget: float | None):
        self.recognizer, self.touches, self.misses = recognizer, touches, tuple(misses)
        self.search_budget = search_budget
        self.stages = dict.fromkeys(STAGES, 0.0)
        self.searches: list = []                   # this add's recognitions: where new candidate poses come from
        self.fit: JointFit | None = None
        self.result = None
        self._joint = joint

    @property
    def joint(self) -> dict:
        """Every model's joint pose after the add's last fit."""
        return self._joint if self.fit is None else self.fit.joint

    def timed(self, stage: str, fn, *args, **kwargs):
        """``fn(*args, **kwargs)``, its seconds added to this add's ``stage`` (:data:`STAGES`)."""
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            self.stages[stage] += time.perf_counter() - start

    def run(self, given, world, slipped: set, *, joint_search: bool):
        """Steps 1-6 for the touch ``given`` (:class:`~tactrec.io.session.SessionTouch`), ``world`` its
        data in the world frame; ``slipped``: the touches the result before it called slipped.
        Returns the session's result."""
        earlier = any(i not in slipped for i in range(len(self.touches)))
        own = self.timed("own", self._own, world, slipped)
        self.touches = self.touches.with_record(TouchRecord(given, world, own))
        self.searches.append(own)
        self.fit = JointFit(self.recognizer, self.touches, self.misses, self._joint, self.searches)
        self.result = self.timed("joint", self.fit)
        if joint_search and earlier and self.recognizer.method.scores_context and world.contacts is None:
            self._search_jointly(slipped, own.work)
        return self.result

    # ------------------------------------------------------------------ step 1
    def standing(self, slipped: set) -> list[str]:
        """The models whose joint pose so far is consistent with every touch but those ``slipped``:
        the hypotheses a later touch is searched among first (:meth:`_own`)."""
        return [name for name, h in self._joint.items()
                if h.consistent and all(c for i, c in enumerate(h.consistent) if i not in slipped)]

    def _own(self, world, slipped: set):
        """Step 1: the new touch's own recognition.  Once earlier touches leave standing hypotheses
        (:meth:`standing`) that are not every model, it is searched among their models first, and
        that search is its own where one of them fits it (the fit test, against its fit limit); else
        the touch rules them all out and the whole catalogue is searched, that search its own (the
        first one's seconds count in the add's ``own`` stage).  A session's later touches cost what
        its standing models cost, not what the catalogue does."""
        if world.contacts is not None:
            return self._pooled(world, slipped)
        standing = self.standing(slipped)
        if standing and len(standing) < len(self.recognizer.models):
            first = self.recognizer.recognize(world, among=standing)
            errors = [r.error / r.scale for r in first.ranking if r.ok]
            if errors and fits(min(errors), fit_limit(first.touch, self.touches.floor), len(first.touch.points)):
                return first
        return self.recognizer.recognize(world)

    def _pooled(self, world, slipped: set):
        """Step 1 for a touch of contacts: a contact alone poses nothing, so its search is that of every
        contact of the session's kept touches of contacts and its own together (world frame,
        :mod:`tactrec.engine.contacts`); the recognition is given the touch's own features, so that
        each contact counts once in the joint fits.  Until they can be posed
        (:func:`tactrec.io.contacts.spread_problem`) no model is searched."""
        from ..features import Touch
        from ..io.contacts import spread_problem
        from ..io.touch import TactileData

        pooled = self.touches.joined_contacts([i for i in range(len(self.touches)) if i not in slipped])
        pooled = world.contacts if pooled is None else pooled.joined(world.contacts)
        own = Touch.from_data(world)
        problem = spread_problem(pooled)
        if problem is not None:
            return self.recognizer.unposed(own, problem)
        found = self.recognizer.recognize(TactileData.from_contacts(pooled, units=world.units, source=world.source))
        return dataclasses.replace(found, touch=own)

    # ------------------------------------------------------------------ step 5
    def kept(self) -> list[int]:
        """The touches the add's result uses: all but those it calls slipped."""
        slipped = () if self.result is None else self.result.slipped
        return [i for i in range(len(self.touches)) if i not in slipped]

    def _search_jointly(self, slipped: set, work: int) -> None:
        """Step 5, in two passes over the same starts, the new touch then the one kept before it
        (:data:`STARTS`), each search with every other touch kept in the score: while no pose found
        fits every touch kept at their noise, over the models the new touch fits on its own whose
        pose does not fit them all (every such model once the best pose fits them all but not at
        their noise); then, once the best pose fits them at their noise, over its rivals
        (:meth:`rivals`).  A search of the first pass stops once a pose fits the touches as well
        as their own searches fit each, so it may stop on the best model before it reached a
        rival's pose: the second looks for the rivals' own, and stops once a pose of one fits as
        well as the best's (or the start touch's own fit limit, where that is larger).  Each pass
        has its budget, ``work`` (what the touch's own search spent) x ``search_budget``, shared by
        its searches: a rival is searched even where finding the best took the first pass's."""
        touches = self.touches
        use = [i for i in range(len(touches)) if i not in slipped]
        fit = touches.pooled(touches.reference()[use], use)
        starts = [i for i in use[::-1] if touches.records[i].world.contacts is None][:STARTS]
        for rivals in (False, True):
            budget = np.inf if self.search_budget is None or work <= 0 else self.search_budget * work
            for start in starts:
                explained = self._explained(slipped)
                if budget <= 0:
                    break
                if explained and self._fitted():
                    among = self.rivals(use) if rivals else []
                elif rivals:
                    return                                    # the best pose itself was not found
                else:
                    among = self.unexplained(slipped, every=explained)
                if not among:
                    break
                # a rival is level once a pose of it fits as well as the best's does
                goal = min(fit, self.result.ranking[0].error) if rivals else fit
                budget -= self._search_from(start, use, among, goal, budget)

    def _search_from(self, start: int, use: list[int], among: list[str], fit: float, budget: float) -> int:
        """One search of step 5: touch ``start`` searched again over the models ``among`` with the
        other touches ``use`` in its score, until a pose fits them as well as ``fit`` or ``budget``
        is spent; the joint fit is made again on its poses.  Returns the work it spent."""
        records = self.touches.records
        others = [records[i] for i in use if i != start]
        context = Context([c for r in others for c in r.features.data.curves],          # the points each kept
                          fit, [r.tip for r in others for _ in r.features.data.curves],
                          [c for r in others for c in r.surface_curves])
        found = self.timed("context", self.recognizer.recognize_jointly, records[start].features.data, context,
                           among=among, budget=None if np.isinf(budget) else int(budget))
        self.searches.append(found)
        self.result = self.timed("joint", self.fit, found)
        return found.work

    def _explained(self, slipped: set) -> bool:
        """Whether the best model's joint pose is consistent with every touch but those ``slipped``
        before this one, the new touch included even if step 4 calls it slipped: a touch is only
        left out as slipped once the search scoring its poses on every touch (step 5) has found
        none that fits them all."""
        best = self.result.ranking[0] if self.result.ranking else None              # the best fit
        return best is not None and all(c for i, c in enumerate(best.consistent) if i not in slipped)

    def _fitted(self) -> bool:
        """Whether the best model's joint pose fits the touches kept as well as their noise allows
        (:meth:`~.touches.Touches.fitted_at`): then no search can fit them better."""
        return bool(self.result.ranking) and self.touches.fitted_at(self.result.ranking[0].error, self.kept())

    def unexplained(self, slipped: set, *, every: bool = False) -> list[str]:
        """The models step 5 searches: those whose joint pose is not consistent with every touch but
        those ``slipped`` before (``every``: whether or not it is, for a best pose consistent with
        every touch but not a fit under their noise, which another pose may beat), and that the new
        touch fits on its own (its own search's error within :meth:`~.touches.Touches.limits`).  When
        that search fitted no model (its best error not as good as its fit limit, by the fit test),
        its errors rule nothing out: every such model is searched, those it deferred unrefined
        included."""
        touches = self.touches
        new = touches.records[-1]
        fitted = fits(touches.reference()[-1], fit_limit(new.features, touches.floor), len(new.points))
        limit = touches.limits()[-1] if fitted else np.inf
        out = []
        for r in new.own.ranking:
            h = self.result.hypothesis(r.model)
            fits_all = h is not None and all(c for i, c in enumerate(h.consistent) if i not in slipped)
            own = r.error / r.scale if r.ok else (np.inf if r.outcome is Outcome.DEFERRED else None)
            if own is not None and own <= limit and (every or not fits_all):
                out.append(r.model)
        return out

    def rivals(self, use: list[int]) -> list[str]:
        """The models step 5 searches once the best pose fits every touch at their noise: those every
        touch ``use`` (indices) fits on its own (its own search's error within
        :meth:`~.touches.Touches.limits`) whose joint pose does not fit them all at their noise, as
        the best's does.  Such a joint pose may be one the search missed, and a model is never
        counted out on a pose no search looked for: a worse joint fit is evidence only once the
        search has looked."""
        touches = self.touches
        limits = touches.limits()
        own = [{r.model: r.error / r.scale for r in touches.records[i].own.ranking if r.ok} for i in use]
        best = self.result.ranking[0].model
        out = []
        for h in self.result.ranking:
            if h.model == best or (all(h.consistent[i] for i in use) and touches.fitted_at(h.error, use)):
                continue
            if all(h.model in errors and errors[h.model] <= limits[i] for i, errors in zip(use, own)):
                out.append(h.model)
        return out
