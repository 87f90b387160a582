"""Several touches of one still object: one pose per model that fits them all.

A :class:`Session` keeps the touches of one object in a common *world*
frame, one :class:`~.record.TouchRecord` per touch.  Adding a touch
(:meth:`Session.add`) costs one recognition of that touch and a joint
refinement (more searches only in step 5):

1. the touch, moved into the world frame by its ``sensor2world`` pose, is
   recognised on its own by the recognizer's method; each accepted model's
   registration is then a world-to-model pose.  Once earlier touches leave
   standing hypotheses (models whose joint pose is consistent with every
   touch kept), it is searched among those models first, and over the whole
   catalogue only where none of them fits it (the fit test of step 3 against
   its fit limit): a later touch of a session on a large catalogue costs what
   the standing models cost (:meth:`.add.Add.standing`);
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
   score (:meth:`tactrec.recognition.Recognizer.recognize_jointly`, the other
   touches as a :class:`~tactrec.features.Context`), and steps 2-4 run
   again on its poses; if still no pose fits them all at their noise, the
   touch kept before it is searched the same way with the others in its score (:data:`STARTS`).  Once the best pose
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
   (:meth:`Session.add_miss`, :mod:`tactrec.missed`).

Touches of round tips (:mod:`tactrec.tip`), of one radius or several: each
touch's distances are measured against the model offset by its own tip; step
5 screens the other touches moved onto the surface (by their own estimates).
A missed line is measured against the model itself (:mod:`tactrec.missed`).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..errors import InputError
from ..io.session import SessionTouch, rigid_pose
from ..io.touch import TactileData
from ..probability import FLOOR
from . import family as _family
from .add import STAGES, STARTS, Add
from .joint import session_evidence
from .result import SessionResult
from .touches import Touches

__all__ = ["Session", "STAGES", "FLOOR", "STARTS"]


class Session:
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

    The session keeps its touches (:attr:`touches`), the lines that met nothing, every model's
    joint pose and the last result; an add's own work lives in an :class:`~.add.Add` made for it.
    """

    def __init__(self, recognizer, *, joint_search: bool = True, search_budget: float | None = 1.0):
        if search_budget is not None and not (np.isfinite(search_budget) and search_budget >= 0):
            raise ValueError(f"search_budget must be a non-negative number or None, not {search_budget!r}")
        self.joint_search = joint_search
        self.search_budget = search_budget
        self.recognizer = recognizer
        self.touches = Touches((), recognizer.floor)
        self.misses: tuple = ()                 # lines that met nothing, world frame
        self.joint: dict = {}                   # every model's joint pose (and its family, once asked)
        self.result: SessionResult | None = None

    # ------------------------------------------------------------------ the touches
    @property
    def records(self) -> tuple:
        """One :class:`~.record.TouchRecord` per touch, in order."""
        return self.touches.records

    @property
    def features(self) -> list:
        """Each touch's :class:`~tactrec.features.Touch` (world frame), in order."""
        return self.touches.features

    @property
    def tips(self) -> np.ndarray:
        """Each touch's tip radius ``(N,)``, data units."""
        return self.touches.tips

    @property
    def world(self) -> list:
        """Each touch's data in the world frame, in order."""
        return self.touches.world

    @property
    def floor(self) -> float:
        """The method's ``floor`` (a fit's mean distance per unit radius on noise-free data), or :data:`FLOOR`."""
        return self.recognizer.floor

    def contacts(self) -> np.ndarray:
        """Each touch's contact in the world frame ``(N, 3)``: the one its data give, else its estimate's."""
        return self.touches.contacts()

    def kept(self) -> list[int]:
        """The touches the session's result uses: all but those it calls slipped."""
        slipped = () if self.result is None else self.result.slipped
        return [i for i in range(len(self.touches)) if i not in slipped]

    def pooled(self, values, touches) -> float:
        """The points-weighted mean of per-touch ``values`` (one per index of ``touches``)."""
        return self.touches.pooled(values, touches)

    def limit(self, touches) -> float:
        """The points-weighted mean of the fit limits of the touches ``touches`` (indices)."""
        return self.touches.limit(touches)

    def fitted_at(self, error: float, touches) -> bool:
        """Whether a pose of mean distance ``error`` over the touches ``touches`` fits them as well as
        their noise allows (:meth:`~.touches.Touches.fitted_at`)."""
        return self.touches.fitted_at(error, touches)

    def consistent(self, name: str, per_touch: np.ndarray) -> np.ndarray:
        """Which touches are consistent with poses of model ``name`` whose per-touch mean distances are
        ``per_touch (h, N)`` (:meth:`~.touches.Touches.consistent`)."""
        return self.touches.consistent(name, per_touch)

    # ------------------------------------------------------------------ adding
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
        step = Add(self.recognizer, self.touches, self.misses, self.joint, search_budget=self.search_budget)
        result = step.run(touch, world, slipped, joint_search=self.joint_search)
        result = dataclasses.replace(result, seconds=time.perf_counter() - start, stages=dict(step.stages),
                                     searched=tuple((s.work, s.allowed) for s in step.searches))
        self.touches, self.joint, self.result = step.touches, step.joint, result
        return result

    def add_miss(self, line, sensor2world=None) -> SessionResult | None:
        """Add a touch whose approach ``line`` (:class:`~tactrec.io.session.MissedLine`, sensor frame;
        ``sensor2world`` as for :meth:`add`) met nothing: evidence against every pose whose surface
        it cuts (:mod:`tactrec.missed`).  The result (None before any touch met the object) is the last one's
        with the probabilities weighed again; nothing is searched."""
        start = time.perf_counter()
        if sensor2world is not None:
            line = line.transformed(*rigid_pose(*sensor2world, "missed line"))
        misses = self.misses + (line,)
        if self.result is None:
            self.misses = misses
            return None
        found = session_evidence(self.recognizer, self.touches, misses, self.result.ranking, self.kept())
        self.misses = misses
        self.result = dataclasses.replace(self.result, evidence=found, missed=len(misses),
                                          seconds=time.perf_counter() - start, stages=dict.fromkeys(STAGES, 0.0),
                                          searched=())
        return self.result

    # ------------------------------------------------------------------ what comes next
    def family(self, name: str) -> np.ndarray:
        """Model ``name``'s pose and the poses along the motions its touches leave free, ``(p, 3, 4)``
        (:func:`.family.free_poses`; computed when asked, for the models :meth:`next` weighs)."""
        h = self.joint[name]
        if h.poses is None:
            model = next(e.model for e in self.recognizer.models if e.name == name)
            kept = self.kept()
            use = np.isin(np.arange(len(self.touches)), kept)
            x = np.concatenate([self.records[i].points for i in kept]) * h.scale
            h = dataclasses.replace(h, poses=_family.free_poses(self.touches, model, h, use, x))
            self.joint[name] = h
        return h.poses

    def next(self, *, radius: float, angle: float = 60.0, candidates: int | None = None, rng=None):
        """Where to touch next: an approach line and the curves to trace (:func:`tactrec.proposal.propose`;
        ``candidates`` None: its :data:`~tactrec.proposal.CANDIDATES`)."""
        from ..proposal import CANDIDATES, propose

        return propose(self, radius=radius, angle=angle, candidates=candidates or CANDIDATES, rng=rng)
