"""Method ``fast``'s search state: what the search knows of each model, and when it may stop (see
:mod:`tactrec.methods.fast`)."""

from __future__ import annotations

import numpy as np

from ..linalg import clearly_less
from ..probability import fit_limit, noise_fit, plausible_fit, resolution
from ..registration.result import Registration
from .common import in_model_units
from .fast_stages import hop_stage, polish_stage, tier_span

__all__ = ["State", "error_of", "grid_leaders", "tier_places"]


def error_of(r: Registration | None) -> float:
    """A registration's error in the data's units (inf for none)."""
    return r.error / r.scale if r is not None and r.ok else np.inf


def tier_places(config, k: int, model, radius: float) -> int:
    """How many places tier ``k`` takes on a mesh ``model`` for a touch of ``radius`` (model units):
    its vertices, or in a field tier one a grid cell ``screen_step x radius`` across and a direction
    of the normals in it (:func:`tactrec.engine.screen.screen_places`): a surface of area ``A``
    meets about ``1.5 A / size^2`` cells (the mean of ``|n_x| + |n_y| + |n_z|`` over directions),
    and where that reaches past the tier's span the count stops there; else the cells' second
    directions are counted (on the vertices in index order, at the cell size rounded down to a
    quarter octave, kept on the model: :attr:`~tactrec.surfaces.mesh.MeshModel.search_memo`), and no
    more places than vertices.  A folded tier's are the folded cells' places alone, counted so."""
    vertices = len(model.vertices)
    if config.tiers[k].rotations != "field":
        return vertices
    size = max(config.screen_step * radius, 1e-12)
    cells = int(np.ceil(1.5 * model.area / size ** 2))
    _, stop = tier_span(config.tiers, k)
    folded = config.tiers[k].folded
    if stop is not None and cells >= stop and not folded:
        return min(vertices, cells)
    counted = 2.0 ** (np.floor(4.0 * np.log2(size)) / 4.0)        # smaller cells: at least as many places
    key = ("places", float(counted), float(config.tilt_step))
    memo = getattr(model, "search_memo", {})
    if key not in memo:
        from ..registration.mesh_fast import first_per_cell, first_per_place

        order = np.arange(vertices)
        places = first_per_place(model, order, counted, config.tilt_step)
        folded_places = first_per_place(model, order, counted, config.tilt_step, folded=True)
        memo[key] = (len(places) - len(first_per_cell(model, order, counted)), len(folded_places))
    extra, in_folds = memo[key]
    return min(vertices, in_folds if folded else cells + extra)


class State:
    """What the search knows: each model's best registration, best cheap score and next tier."""

    def __init__(self, touch, models, meshes, config):
        self.touch, self.config = touch, config
        self.best: dict[int, Registration] = {}
        self.rejected: dict[int, str] = {}
        self.cheapest = {i: np.inf for i in meshes}
        self.deferred = {i: np.inf for i in meshes}
        self.tried = {i: 0 for i in meshes}
        self.grids: dict[int, tuple] = {}               # each model's grid: the pose it is about, span, rounds
        self.next = {i: 0 for i in meshes}
        self.models, self.counts = models, {}
        self.limit = max(fit_limit(touch, config.floor), touch.fit)      # a caller's joint fit, with a context
        #: the data's noise lies below the fit floor: the true pose fits far within the limit
        self.noise_free = bool(noise_fit(touch.noise) <= resolution(touch, config.floor))
        # a best error this far above the limit may still be a fit under the noise; beyond it the true
        # pose was missed somewhere, and no model's first tiers rule it out.  Where the noise's own
        # spread stays below the floor (noise-free data), the limit is the floor, not a draw of the
        # noise: a best error above it is such a miss
        self.plausible = plausible_fit(self.limit, touch.noise, len(touch.joint_points), config.within)

    def places(self, i: int, k: int) -> int:
        """How many places tier ``k`` takes on model ``i`` (:func:`tier_places`), for this touch."""
        if (i, k) not in self.counts:
            model = self.models[i].model
            self.counts[i, k] = tier_places(self.config, k, model, in_model_units(self.touch, model).radius)
        return self.counts[i, k]

    def error(self, i: int) -> float:
        return error_of(self.best.get(i))

    def standing(self, i: int) -> float:
        """The best score known on model ``i`` (data units): its best refined error, or the cheap
        score of a pose deferred unrefined, whichever is lower."""
        return min(self.error(i), self.deferred.get(i, np.inf))

    def leader(self) -> tuple[int | None, float]:
        ranked = sorted(self.best, key=lambda i: (self.error(i), i))
        return (ranked[0], self.error(ranked[0])) if ranked else (None, np.inf)

    def leader_at(self) -> tuple[int | None, np.ndarray | None]:
        """The leading model and its registration's contact (model coordinates; None for none)."""
        leader, _ = self.leader()
        return leader, (None if leader is None else self.best[leader].location)

    def waiting(self) -> list[int]:
        return [i for i in self.next if i not in self.rejected and self.next[i] < len(self.config.tiers)]

    def clear(self) -> bool:
        """Whether the best is a plausible fit (within ``within`` standard errors of the fit limit; on
        noise-free data, within the limit) and
        every other model's standing lies beyond ``ratio`` x its error."""
        leader, e1 = self.leader()
        if leader is None or not np.isfinite(e1) or e1 > self.plausible:
            return False
        return all(self.standing(i) > self.config.ratio * e1 for i in set(self.cheapest) | set(self.best)
                   if i != leader)

    def contending(self) -> list[int]:
        """The models whose next tier runs in this round (the search has not settled, so the best is
        not clear): those whose standing lies within ``ratio`` x the best error or the fit limit,
        whichever is higher (every model while none has an error); when none does, the deferred
        ones whose next tier is the shallowest."""
        waiting = self.waiting()
        _, e1 = self.leader()
        if not np.isfinite(e1):
            near = waiting
        else:
            near = [i for i in waiting if self.standing(i) <= self.config.ratio * max(e1, self.limit)]
        if near:
            return near
        shallowest = min((self.next[i] for i in waiting), default=None)
        return [i for i in waiting if self.next[i] == shallowest]

    def settled(self) -> bool:
        """Whether the search may stop: the best error is a fit (within the data's noise, or ``floor``
        x the touch's radius), or the best is clear of the others (:meth:`clear`)."""
        leader, e1 = self.leader()
        if leader is None or not np.isfinite(e1):
            return False
        return bool(e1 <= self.limit or self.clear())


def grid_leaders(state: State, meshes: list[int], runner, room, work: int, models: int) -> int:
    """While the best pose lies beyond a plausible fit (:attr:`State.plausible`), the leading poses
    (within ``ratio`` of the best, the ``models`` best models), each first polished (the final
    polish's steps, :func:`~.fast_stages.polish_stage`), then searched again about themselves
    (:func:`~.fast_stages.hop_stage`) as far as ``room(work)`` grids go: a round that finds nothing
    better ends that pose's grid (its nodes' basins cover its span, and a finer grid covers less);
    one that lowers the error but not by half halves the grid; three rounds a pose at the most.  A
    pose a tier finds later takes a grid of its own.  Returns the work."""
    config, spent = state.config, 0
    while True:
        _, e1 = state.leader()
        if not (np.isfinite(e1) and e1 > state.plausible):
            break
        leading = [i for i in sorted(state.best, key=lambda i: (state.error(i), i))
                   if i in meshes and state.best[i].ok and state.error(i) <= config.ratio * e1][:models]
        new = [i for i in leading if i not in state.grids or state.grids[i][0] is not state.best[i]]
        # a new pose first takes the final polish's steps on all points: a tier's refinement
        # ends a step or two short of a fit the polish reaches
        items = [state.best[i] for i in new]
        for i, found in zip(new, runner.map(polish_stage, new, state.touch, config, False, items=items)):
            spent += found.queries
            state.best[i] = found.registration
            state.grids[i] = (state.best[i], 1.0, 0)                          # about a pose, its span, rounds
        _, e1 = state.leader()
        if new and not e1 > state.plausible:
            break
        near = [i for i in leading if state.grids[i][2] < 3][:max(0, room(work + spent))]
        if not near:
            break
        items = [state.grids[i][:2] for i in near]
        for i, found in zip(near, runner.map(hop_stage, near, state.touch, config, items=items)):
            spent += found.queries
            before, (_, span, rounds) = state.error(i), state.grids[i]
            if not clearly_less(error_of(found.registration), before):
                state.grids[i] = (state.best[i], span, 3)
                continue
            state.best[i] = found.registration
            halved = error_of(state.best[i]) <= 0.5 * before
            state.grids[i] = (state.best[i], span if halved else span / 2, rounds + 1)
    return spent
