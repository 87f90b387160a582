"""Method ``fast``'s indexed tier: the catalogue's best places by the index of places
(:mod:`tactrec.index`), screened on their models' fields in rounds.

The first tier of the schedule (:data:`~tactrec.methods.fast_config.TIERS`) takes, over the models
searched, the ``places`` x models places whose rings lie nearest the touch's
(:meth:`tactrec.index.PlaceIndex.ranked`): as many places as a tier of each model's best
``places`` would, but chosen across the catalogue, so that a model whose surface is nothing like
the touch's takes none.  They are screened in rounds, best first: the first round
``index_round`` places and every model's own best ``index_floor``, each later one twice as many, over the models whose turn it is (the
search's own rule, :meth:`~tactrec.methods.fast_state.State.contending`: the leaders first while
they stand near the best; else every model with places left).  A model's first tier ends when
its places in the ranking are all screened; a search that settles (a fit, or a clear best) stops
between rounds, so most touches screen a few thousand places of a catalogue, not every model's 500.

Every model's own best few places are in the first round because differences of rings below the
touch's noise and a place's offset from the contact (up to a cell) mean nothing: where two models
share the touched surface (a face two parts have, spheres of 30 and 31 mm), the catalogue's order
may put all of one's places before the other's, and a search that stopped on the first fit would
never pose the other, and call the answer sure.  With its best places screened, each model has a
cheap score, and the search's rules (deferral, a clear best) judge it as in any tier.

Each model screens its places of a round at every rotation on its field
(:func:`~tactrec.methods.fast_stages.field_poses`), keeping ``index_keep`` hypotheses a place for
the field steps, then the selection and refinement of any tier.
"""

from __future__ import annotations

import numpy as np

from ..engine import LOOKUP_COST
from ..registration.result import Outcome
from .common import in_model_units
from .fast_stages import OVERSIZED, Cheap, field_poses, fitted, oversized, touch_gaps

__all__ = ["IndexedTier", "indexed_stage", "round_cost"]


class IndexedTier:
    """One touch's progress through the indexed tier ``k`` over the mesh models ``meshes``."""

    def __init__(self, index, touch, meshes: list[int], config, k: int):
        self.k, self.config = k, config
        self.ranked = index.ranked(touch, meshes, config.tiers[k].places * len(meshes))
        self.floor = index.each_best(touch, meshes, config.index_floor)
        self.done = np.zeros(len(self.ranked), dtype=bool)
        self.rounds = 0
        size = max(meshes) + 1
        self._floored = np.bincount(self.floor.model, minlength=size) > 0
        self._left = np.bincount(self.ranked.model, minlength=size)      # each model's places not yet screened

    @staticmethod
    def _keys(ranked) -> np.ndarray:
        return (ranked.model * (2 ** 31) + ranked.vertex) * 2 + (ranked.sign > 0)

    def left(self, i: int) -> bool:
        """Whether model ``i`` has places not yet screened: its own best before the first round, or
        places of the ranking."""
        return bool((self.rounds == 0 and self._floored[i]) or self._left[i] > 0)

    def next_round(self, group: list[int]) -> dict[int, dict[int, np.ndarray]]:
        """The next round's places of the models ``group``: per model, per side of the normal, its
        vertices in the ranking's order; marked screened."""
        size = self.config.index_round * 2 ** self.rounds
        take = np.flatnonzero(~self.done & np.isin(self.ranked.model, group))[:size]
        model, vertex, sign = self.ranked.model[take], self.ranked.vertex[take], self.ranked.sign[take]
        if self.rounds == 0:                    # and every model's own best places
            floor = self.floor
            extra = np.isin(floor.model, group) & ~np.isin(self._keys(floor), self._keys(self.ranked)[take])
            model, vertex, sign = (np.concatenate([a, b[extra]]) for a, b in
                                   ((model, floor.model), (vertex, floor.vertex), (sign, floor.sign)))
            self.done |= np.isin(self._keys(self.ranked), self._keys(floor)[np.isin(floor.model, group)])
        self.done[take] = True
        self.rounds += 1
        self._left = np.bincount(self.ranked.model[~self.done], minlength=len(self._left))
        out: dict[int, dict[int, np.ndarray]] = {}
        for i in np.unique(model):
            mine = model == i
            out[int(i)] = {int(s): vertex[mine & (sign == s)] for s in np.unique(sign[mine])}
        return out


def round_cost(config, spots: dict[int, dict[int, np.ndarray]], curves: int, context: int) -> int:
    """About how many closest-point queries a round of the indexed tier costs (as
    :func:`~tactrec.methods.fast.tier_cost` counts a field tier)."""
    total = 0.0
    for sides in spots.values():
        for vertices in sides.values():
            alive, lookups = len(vertices), 0
            for rotations, per_curve, share in config.screen_stages:
                lookups += alive * rotations * (per_curve * curves + context)
                alive = min(alive, max(config.screen_keep, int(np.ceil(share * alive))))
            kept = min(config.screen_keep, config.index_keep * len(vertices))
            lookups += kept * (config.field_steps + 1) * 3 * config.coarse_points * curves
            total += 2 * (lookups * LOOKUP_COST + 2 * config.refine * config.coarse_points * curves)
        total += config.refine * config.iterations * curves * 3 * config.coarse_points
    return int(total)


def indexed_stage(held, indices, touch, config, k: int, spots: list[dict[int, np.ndarray]]) -> list[Cheap]:
    """Step 1 of an indexed round on each mesh model: its places of the round (``spots``: per side of
    the normal, vertices) screened on its field; its best ``refine`` poses and their cheap scores."""
    tier = config.tiers[k]
    out = []
    for index, sides in zip(indices, spots):
        model = held.entries[index].model
        t = in_model_units(touch, model)
        if oversized(t, model):
            out.append(OVERSIZED)
            continue
        x = t.joint_subset(config.coarse_points)
        exact = t.exact(model, config.coarse_points)
        poses, queries, tried = [], 0, 0
        for sign, _ in t.sides:
            vertices = sides.get(sign)
            if vertices is None or len(vertices) == 0:
                continue
            seen, s, g = t.searched(model, sign)                 # (a) of tactrec.tip
            _, fit = touch_gaps(held, index, seen, s, g, sign)
            context = s.screen_subset(config.coarse_points)[len(s.subset(config.coarse_points)):] \
                if t.context else None
            R, tr, score, q, n = field_poses(seen, s, g, sign, vertices, fit, tier, config, context, exact, x,
                                             keep=min(config.screen_keep, config.index_keep * len(vertices)))
            tried, queries = tried + n, queries + q
            poses.append((R, tr, score, np.full(len(R), sign)))
        if not poses:
            out.append(Cheap(Outcome.NOT_SEARCHED, int(queries), tried))
            continue
        out.append(fitted(poses, config, t, queries, tried))
    return out

