"""Method ``fast``: one search over every model, coarse to fine, with a budget.

The hypotheses are (model, place, rotation about the normal, tilt of the
normal, sign of the normal).  The search takes them in *tiers*
(:data:`TIERS`), each a step coarse to fine: the catalogue's best 500
places a model by the index of places (:mod:`tactrec.index`: the rings of
the surface about each place, read as a touch reads them), at every
rotation, screened on their models' distance fields
(:mod:`tactrec.engine.screen`) in rounds, best first
(:mod:`.fast_index`), or each model's best 500 by curvature for a touch
whose curves reach no ring; for a touch whose normals disagree across
scales (:attr:`tactrec.features.Touch.scales`: it lies on a sharp, thin or
folded place, where no fit reads the curvature), the best 500 *folded*
places, cells whose normals lie more than ``tilt_step`` degrees apart; the
few places whose curvature best matches the data's, posed by their
principal frames (exact vertices and frames,
which the screen's grid of places and turns can fall between); every other
place at every rotation on the field: the curvature index orders the
places, it does not filter them.  A field tier's place is a grid cell and a
direction of the normals in it (:func:`tactrec.engine.screen.screen_places`):
a cell on a crest or a thin part holds normals tens of degrees apart, and
each direction is posed on its own.  Last, every place again with the data's
normal tilted every ``tilt_step`` degrees out to 60, for a contact on a
sharp or thin feature, where no fit of the curves gives the surface's
normal (each of its best seeds then set on a dense local grid of turns and
shifts, which bridges the tilts' grid and the basin of the exact steps).
A tier on a set of models is

1. *cheap stage* (per model, :func:`cheap_stage`): the tier's new hypotheses are
   posed from frames (:func:`tactrec.registration.mesh_fast.frame_poses`) and
   take ``cheap_steps`` Gauss-Newton steps on exact distances from
   ``coarse_points`` points a curve (after the first, only the best eighth,
   at least ``screen``, go on; with a context, the first step, which every
   hypothesis takes, scores the context on one point a curve, its middle:
   :meth:`tactrec.features.Touch.screen_subset`); or, in a field tier, are
   screened on the field in ``screen_stages`` (the best ``screen_keep`` take
   ``field_steps`` Gauss-Newton steps on the field and the best ``2 refine``
   of those one exact step); each place keeps its best rotation and the
   model its best ``refine`` poses;
2. *selection* (across models): a pose is refined when its cheap score lies
   within ``ratio`` x the best error so far (or the tier's best cheap score);
   the others are deferred, not dropped;
3. *refinement* (per model, :func:`refine_stage`): ``iterations`` exact steps on
   three times the points, then two on all points for the model's best.
   Every refinement of more than one step extrapolates its steps from the
   last ``history`` (Anderson acceleration, :mod:`tactrec.registration.anderson`):
   on a scan's facets a plain step slides a weakly held pose a few per cent
   of the way to the fit, for a hundred steps.

The first tier runs on every model.  Each later round runs the next tier of
the models in contention (:meth:`State.contending`): those whose best score
lies within ``ratio`` x the best error (or the fit limit, where higher),
whether or not the best fits; the deferred models, shallowest tier first,
when none contends.  A model far behind is not ruled out, it waits: while
nothing fits, the leading models' deeper tiers run first, and the others'
when the leaders' are spent, unless the budget ends the search first (a
round it cannot afford stops it, whichever models wait; on the P3 touches
of the other-source scans that went past the first tier, the true model
led in 32 of 37 after it;
deepening every model there, as before, gave no fit 4 where this gives 3,
and on the YCB and CAD sets 2 where this gives 1).  The search
stops (:meth:`State.settled`) when the best error is a *fit*: within what
the data's own noise allows (the mean distance of a perfect fit, ``sigma
sqrt(2 / pi)``, ``sigma`` from the curves' third differences) or ``floor`` x
the touch's radius on noise-free data (or, for a touch with a context, the
larger joint fit its caller gives: :attr:`tactrec.features.Touch.fit`); or
when the best is *clear*: a plausible fit whose error every other model's
standing exceeds by ``ratio``.  No later tier could then change the model,
only move its pose within what the noise cannot tell apart (the final polish
still refines it): on noisy data the true pose's error lies above the fit
limit about half the time, and such a search went on through the leader's
deepest tiers for nothing.  On noise-free data the truth fits orders of
magnitude within the limit, and a leader above it is a stall, however far
ahead (on the other-source P3 touches, 4 of the 12 that ended on no fit had
stopped so, clear between the limit and the noise's allowance).  Else it
stops when nothing is left.

Before each round, while the best error is beyond a plausible fit of data
whose noise lies below the fit floor (``floor`` x the touch's radius), the
fit test steers the search (:func:`~tactrec.methods.fast_state.grid_leaders`):
the leader's pose, and when the tiers end the leading poses (within
``ratio`` of the best, at most ``polish`` models), each pose once, first
take the final polish's steps (a tier's refinement often ends a step or two
short of the fit), and those still beyond are searched again about
themselves, each with its best alternative, on a grid of ``hop_steps``
turns and shifts in each of the six directions, ``hop_angle``
degrees and ``hop_shift`` x the touch's radius out, every pose refined on
exact distances.  On a scan's facets, at a sharp or thin place, the exact
steps from a start a few degrees off settle on a nearby pose that fits a few
times worse than the truth (their basin is about 2 degrees and 0.2 mm, the
search's grids are coarser); the grid's step is that basin, so the true pose
lies in the basin of one of its starts.  A round that finds nothing better
ends the pose's grid (its nodes' basins cover its span; a finer grid covers
less); one that lowers the error but not by half halves the grid, and a
pose takes three rounds at the most.  A stall found in the first tier is so
mended before the deeper tiers run on every model (on the other-source P3
touches of ``tactrec bench fast-vs-paper`` the grids after the last tier
alone left 54 of 140 touches to run the tilted tier).  The grids' work is
counted apart from the tiers' budget, within as much again: charged to it,
they took the tilted tier's room from touches that need it.  On noisy data
a stall's error lies within what the noise allows, and a best pose beyond it
is a miss elsewhere, which no local search mends (on the hard touches of
``tactrec bench fast-vs-paper`` it mended none of 55 and cost twice the
p95).  ``among`` limits a search to chosen models (the budget counts those
alone).  It also stops before a round whose estimated cost would take the
work (closest-point queries) past ``budget`` per model; such a search is
reported as not settled (the budget counts per model and per normal tried:
twice as much without an ``outward`` hint; a caller may give a lower one in
all).  A field lookup counts as :data:`~tactrec.engine.LOOKUP_COST`
of a query, and the final polish is reserved.  A round's cost is counted on
the touch's own curves, and the work on other touches' points at the
touch's share of the points scored, so the budget bounds the poses tried: a
search with other touches in its score (a session's) tries as many as the
touch alone would and spends queries in proportion to the points it scores
(on the first screens, about what the touch alone spends).  The best
``polish`` models then take
``polish_iterations`` more steps on all points.

Every cut in a ranked list (screen, rotations, refinement) orders near-equal
scores by index (:func:`tactrec.linalg.stable_order`), and the arithmetic of
the steps is element-wise, so the same touch gives the same answer on every
CPU.  On closed-form surfaces the registration is
:mod:`tactrec.registration.closedform_fast` (nearest table rows, six-DoF
Gauss-Newton), in the first tier.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..engine import LOOKUP_COST
from ..linalg import clearly_less
from ..registration import mesh_fast
from ..registration.result import Outcome, Registration
from .base import NOT_SEARCHED, SearchOutcome
from .fast_config import TIERS, FastConfig, Tier
from .fast_index import IndexedTier, indexed_stage, round_cost
from .fast_stages import (cheap_stage, closed_form_stage, field_stages, hop_cost, polish_stage, refine_stage,
                          tier_span)
from .fast_state import State, error_of, grid_leaders, tier_places

__all__ = ["FastMethod", "FastConfig", "Tier", "TIERS", "tier_cost", "tier_places", "UNRANKED"]

#: why a model was not searched: the search settled before it reached any of the model's places
UNRANKED = "not searched: the search settled before any of its places, in the index's order"


# ---------------------------------------------------------------------- the search
def tier_cost(config: FastConfig, k: int, signs: int, places: int, curves: int = 3, context: int = 0) -> int:
    """About how many closest-point queries tier ``k`` costs on one model with ``places`` places, a
    pose scored on ``curves`` curves of the touch (the field's screen also on one point of each of
    ``context`` curves of other touches)."""
    tier = config.tiers[k]
    if tier.rotations == "field":
        start, stop = tier_span(config.tiers, k)
        # a contact on a feature is screened with two data normals (engine.screen.data_normals); a
        # tilted tier screens all its tilted normals at once and sets its best seeds on a local grid
        normals, screens, local = 1, 2, 0
        if tier.tilt > 0:
            from ..engine.screen import local_lookups, tilt_rings

            normals = sum(count for _, count in tilt_rings(cone=tier.tilt, step=config.tilt_step))
            screens = 1
            local = local_lookups(config.refine, config.coarse_points * curves) * LOOKUP_COST
        lookups, alive = 0, max(0, min(places, stop if stop is not None else places) - start)
        for rotations, per_curve, share in field_stages(config, tier):
            lookups += alive * normals * rotations * (per_curve * curves + context)
            alive = min(alive, max(config.screen_keep, int(np.ceil(share * alive))))
        lookups += config.screen_keep * (config.field_steps + 1) * 3 * config.coarse_points * curves
        exact = 2 * config.refine * config.coarse_points * curves
        refine = config.refine * config.iterations * curves * 3 * config.coarse_points
        return int(signs * (screens * (lookups * LOOKUP_COST + exact) + local) + refine)
    start, stop = tier_span(config.tiers, k)
    count = max(0, min(places, stop if stop is not None else places) - start)
    poses = count * signs * (2 if tier.rotations == "frames" else 12) * (5 if tier.tilt > 0 else 1)
    screened = min(poses, max(config.screen, poses // 8)) if tier.places is not None else poses
    cheap = curves * config.coarse_points * (poses + (config.cheap_steps - 1) * screened)
    return int(cheap + config.refine * config.iterations * curves * 3 * config.coarse_points)


# a twin of methods/paper.py's PaperMethod by design: both are the hooks of the Method protocol (.base)
class FastMethod:
    """The ``fast`` method (see the module text)."""

    name = "fast"
    scores_context = True
    uses_engine = True
    uses_index = True
    Config = FastConfig

    def configure(self, **options) -> FastConfig:
        return FastConfig.from_options(self.name, options)

    def prepare(self, model) -> None:
        if model.kind == "mesh":
            mesh_fast.prepare(model)

    def search(self, touch, models, config: FastConfig, runner, *, among=None, budget=None,
               index=None) -> SearchOutcome:
        chosen = range(len(models)) if among is None else sorted(among)
        meshes = [i for i in chosen if models[i].model.kind == "mesh"]
        others = [i for i in chosen if models[i].model.kind != "mesh"]
        state = State(touch, models, meshes, config)
        work, settled, depth = 0, False, 0
        for i, found in zip(others, runner.map(closed_form_stage, others, touch, config)):
            state.best[i], work = found.registration, work + found.queries
        signs = len(touch.orientations)
        share = len(touch.points) / len(touch.joint_points)
        polish = config.polish * config.polish_iterations * len(touch.points)        # the final polish's work
        hop = hop_cost(config, len(touch.curves), len(touch.joint_points))          # one model's hopped
        allowed = config.budget * len(chosen) * signs
        allowed = allowed if budget is None else min(allowed, budget)
        fine = bool(meshes) and state.noise_free
        grids = 0                                   # the grids' work, counted apart from the tiers'

        def room(spent: int) -> int:                # the grids' own allowance, as much as the tiers'
            return int((allowed - spent * share) // hop)

        indexed = None                              # the indexed tier's rounds, where the index reads the touch
        if index is not None and meshes and any(t.indexed for t in config.tiers) and index.reads(touch):
            indexed = IndexedTier(index, touch, meshes, config, next(k for k, t in enumerate(config.tiers) if t.indexed))

        while True:
            if fine:                                # the fit test steers: the leader's stall is searched about first
                grids += grid_leaders(state, meshes, runner, room, grids, 1)
            if state.settled():
                twins = indexed.twins(models, *state.leader_at()) if indexed is not None else []
                if not twins:
                    settled = True
                    break
                # before it stops, the models the index cannot tell from the fit's place are posed
                work += self._indexed(state, indexed, indexed.floor_round(twins), runner)
                continue
            group = state.contending()
            if indexed is not None:                 # the indexed tier runs through the catalogue first
                group = [i for i in state.waiting() if state.next[i] == indexed.k] or group
            if not group:
                settled = True                              # every tier has run on every model
                break
            k = state.next[group[0]]
            group = [i for i in group if state.next[i] == k]
            if config.tiers[k].folded and touch.scales.agree:     # no folded place to search first
                state.next.update((i, k + 1) for i in group)
                continue
            if indexed is not None and k == indexed.k:
                finished = [i for i in group if not indexed.left(i)]
                state.next.update((i, k + 1) for i in finished)          # a model without places in the ranking
                group = [i for i in group if i not in finished]
                if not group:
                    continue
                spots = indexed.next_round(group)
                cost = round_cost(config, spots, len(touch.curves), len(touch.context))
                if work > 0 and work * share + cost + polish > allowed:
                    break
                depth = max(depth, k + 1)
                work += self._indexed(state, indexed, spots, runner)
                continue
            cost = sum(tier_cost(config, k, signs, state.places(i, k), len(touch.curves), len(touch.context))
                       for i in group)
            # the budget bounds the poses tried: work on other touches' points (a context) counts as
            # the touch's own share of the points scored, as a round's cost is counted
            if work > 0 and work * share + cost + polish > allowed:
                break
            depth = max(depth, k + 1)
            work += self._tier(state, group, k, runner)
        if fine:                                    # and when the tiers end, the leading models' too
            grids += grid_leaders(state, meshes, runner, room, grids, config.polish)
            settled = settled or state.settled()
        top = [i for i in sorted(state.best, key=lambda i: (state.error(i), i)) if state.best[i].ok][:config.polish]
        polished = runner.map(polish_stage, top, touch, config, False, items=[state.best[i] for i in top])
        for i, found in zip(top, polished):
            state.best[i], work = found.registration, work + found.queries
        return SearchOutcome(self._ranking(state, models), settled, int(work + grids), depth, int(allowed))

    def refit(self, touch, models, config: FastConfig, runner, outcome: SearchOutcome) -> SearchOutcome:
        """``outcome``, a search of nearly the same points as ``touch`` (a few set aside or taken back),
        on ``touch``: each model's registration refined from its pose on the touch's points
        (``polish_iterations`` exact steps), the models rejected or deferred left so; its work added."""
        ranking = list(outcome.ranking)
        ok = [i for i, r in enumerate(ranking) if r.ok]
        work = 0
        for i, found in zip(ok, runner.map(polish_stage, ok, touch, config, True, items=[ranking[i] for i in ok])):
            ranking[i], work = found.registration, work + found.queries
        return dataclasses.replace(outcome, ranking=ranking, work=int(outcome.work + work))

    def _indexed(self, state: State, indexed: IndexedTier, spots: dict, runner) -> int:
        """A round of the indexed tier on ``spots`` (a round of the ranking, or the twins' own best
        places: :meth:`~.fast_index.IndexedTier.floor_round`), each model's next tier left where it
        was: the indexed tier while its places in the ranking are not all screened, else the next
        one, or a deeper tier it had reached.  Returns the work."""
        before = {i: state.next[i] for i in spots}
        work = self._tier(state, sorted(spots), indexed.k, runner, spots) if spots else 0
        for i, k in before.items():
            state.next[i] = k if k > indexed.k or indexed.left(i) else indexed.k + 1
        return work

    @staticmethod
    def _tier(state: State, group: list[int], k: int, runner, spots=None) -> int:
        """Tier ``k`` on the models of ``group`` (with ``spots``, a round of the indexed tier on its
        places: :mod:`.fast_index`): cheap stage, selection, refinement.  Returns the work."""
        touch, config = state.touch, state.config
        if spots is None:
            cheap = dict(zip(group, runner.map(cheap_stage, group, touch, config, k)))
        else:
            cheap = dict(zip(group, runner.map(indexed_stage, group, touch, config, k, items=[spots[i] for i in group])))
        work = sum(c.queries for c in cheap.values())
        posed = {i: c.poses for i, c in cheap.items() if c.outcome is Outcome.FITTED}
        for i, c in cheap.items():
            state.next[i] = k + 1
            state.tried[i] += c.places
            if c.outcome is Outcome.REJECTED:
                state.rejected[i] = c.reason
        for i, poses in posed.items():
            state.cheapest[i] = min(state.cheapest[i], float(poses.score[0]))
        _, e1 = state.leader()
        c_best = min((float(poses.score[0]) for poses in posed.values()), default=np.inf)
        bound = config.ratio * max(min(e1, c_best), state.limit)
        chosen = {i: poses.within(bound) for i, poses in posed.items() if poses.score[0] <= bound}
        for i, poses in posed.items():
            left = poses.score[poses.score > bound]
            if len(left):
                state.deferred[i] = min(state.deferred[i], float(left[0]))
        order = sorted(chosen)
        for i, found in zip(order, runner.map(refine_stage, order, touch, config, items=[chosen[i] for i in order])):
            work += found.queries
            if clearly_less(error_of(found.registration), state.error(i)):
                state.best[i] = found.registration
        return work

    @staticmethod
    def _ranking(state: State, models) -> list[Registration]:
        ranking = []
        for i, entry in enumerate(models):
            if i in state.best:
                r = state.best[i]
                ranking.append(dataclasses.replace(r, candidates=state.tried[i]) if i in state.tried else r)
            elif i in state.rejected:
                ranking.append(Registration.unfitted(entry.name, state.rejected[i]))
            elif i not in state.cheapest:
                ranking.append(Registration.unfitted(entry.name, NOT_SEARCHED, Outcome.NOT_SEARCHED))
            elif not np.isfinite(state.cheapest[i]):            # no place of it screened (the index ranked none)
                ranking.append(Registration.unfitted(entry.name, UNRANKED, Outcome.NOT_SEARCHED))
            else:
                ranking.append(Registration.unfitted(
                    entry.name, f"deferred: its best cheap score {state.cheapest[i]:.3g} stayed beyond "
                    f"{state.config.ratio:g} x the best error", Outcome.DEFERRED, cheap=state.cheapest[i]))
        return ranking
