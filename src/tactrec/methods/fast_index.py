"""Method ``fast``'s indexed tier: the catalogue's best places by the index of places
(:mod:`tactrec.index`), screened on their models' fields in rounds.

The first tier of the schedule (:data:`~tactrec.methods.fast_config.TIERS`) takes, over the models
searched, the ``places`` x models places whose rings lie nearest the touch's
(:meth:`tactrec.index.PlaceIndex.ranked`): as many places as a tier of each model's best
``places`` would, but chosen across the catalogue, so that a model whose surface is nothing like
the touch's takes none.  They are screened in rounds, best first: the first round
``index_round`` places, each later one twice as many, over the models whose turn it is (the
search's own rule, :meth:`~tactrec.methods.fast_state.State.contending`: the leaders first while
they stand near the best; else every model with places left).  A model's first tier ends when
its places in the ranking are all screened; a search that settles (a fit, or a clear best) stops
between rounds, so most touches screen a few thousand places of a catalogue, on the few hundred
models that hold them, not every model's 500: the work of a settled search does not grow with the
models whose surfaces are nothing like the touch's.

Before a search stops, the models the index cannot tell from the fit are posed too
(:meth:`IndexedTier.twins`).  Differences of rings below the touch's noise and a place's offset
from the contact (up to a cell) mean nothing: where two models share the touched surface (a face
two parts have, a ring and its twin with one feature more), the catalogue's order may put all of
one's places behind the other's, and a search that stopped on the first fit would never pose the
other, and call the answer sure.  So the fit's own places about its contact (within a cell and a
half, the offset a place may have; the median of their readings) give the band the index reads
that surface at, widened by what the touch's own noise moves its rings (twice ``within`` times
their spread, :func:`~tactrec.surfaces.mesh_rings.touch_ring_noise`: the true reading lies that
far from the touch's, and a twin's that far from the true one), and every model whose best place
reads within it has its own best places that
do (at most ``index_floor``) screened, and is judged by the search's rules (deferral, a clear
best) as in any tier, before the search may stop.  Where the index reads the touched surface
well, the band is narrow and holds a few models; where it reads it badly, it cannot rule many
out, and they are posed.

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
        self.k, self.config, self.index, self.touch, self.meshes = k, config, index, touch, meshes
        self.ranked = index.ranked(touch, meshes, config.tiers[k].places * len(meshes))
        self.floor = index.each_best(touch, meshes, config.index_floor)
        self.done = np.zeros(len(self.ranked), dtype=bool)
        self.rounds = 0
        size = max(meshes) + 1
        self.floored = np.zeros(size, dtype=bool)                       # whose own best places were screened
        self.reach = -np.inf                                             # the last fit's band (twins)
        self._ring_noise = None                                          # how far the touch's noise moves its rings
        self._left = np.bincount(self.ranked.model, minlength=size)      # each model's places not yet screened
        first = np.r_[True, self.floor.model[1:] != self.floor.model[:-1]] if len(self.floor) else np.zeros(0, bool)
        self._own = np.full(size, np.inf)                                # each model's best place's distance
        self._own[self.floor.model[first]] = self.floor.distance[first]

    @staticmethod
    def _keys(ranked) -> np.ndarray:
        return (ranked.model * (2 ** 31) + ranked.vertex) * 2 + (ranked.sign > 0)

    def left(self, i: int) -> bool:
        """Whether model ``i`` has places of the ranking not yet screened."""
        return bool(self._left[i] > 0)

    def next_round(self, group: list[int]) -> dict[int, dict[int, np.ndarray]]:
        """The next round's places of the models ``group``: per model, per side of the normal, its
        vertices in the ranking's order; marked screened."""
        size = self.config.index_round * 2 ** self.rounds
        take = np.flatnonzero(~self.done & np.isin(self.ranked.model, group))[:size]
        self.done[take] = True
        self.rounds += 1
        self._left = np.bincount(self.ranked.model[~self.done], minlength=len(self._left))
        return self._spots(self.ranked.model[take], self.ranked.vertex[take], self.ranked.sign[take])

    def twins(self, models, leader: int, location: np.ndarray) -> list[int]:
        """The models whose own best places have not been screened and whose best place reads within
        the band of model ``leader``'s places about its fit's contact ``location`` (model
        coordinates: its places within a cell and a half whose normals lie within 37 degrees of the
        nearest one's; the median of their readings, widened by the touch's noise): the index cannot
        tell such a model's surface from the fitted one's, and it may fit as well (module text).
        The band is kept for :meth:`floor_round`."""
        if leader not in self.meshes or location is None:
            return []
        from ..surfaces.mesh_rings import CELL_MM, touch_ring_noise
        from ..units import conversion

        model = models[leader].model
        far = np.linalg.norm(model.vertices - np.asarray(location, dtype=np.float64), axis=1)
        normal = model.fine_curvatures.normal
        near = np.flatnonzero((far <= 1.5 * CELL_MM * conversion("mm", model.units))
                              & (normal @ normal[int(np.argmin(far))] > 0.8))
        # the touch's own noise moves its rings by up to ``within`` x their spread (first order): the
        # fitted surface's true reading, and a twin's, lie that much farther out (triangle inequality)
        if self._ring_noise is None:
            self._ring_noise = max(touch_ring_noise(self.touch, sign) for sign, _ in self.touch.sides)
        noise = self._ring_noise
        reading = self.index.band(self.touch, self.meshes, leader, near)
        self.reach = (np.sqrt(max(reading, 0.0)) + 2.0 * self.config.within * noise) ** 2 if reading >= 0 else reading
        return [int(i) for i in np.flatnonzero((self._own <= self.reach) & ~self.floored) if i != leader]

    def floor_round(self, group: list[int]) -> dict[int, dict[int, np.ndarray]]:
        """Of each of the models ``group``'s own best ``index_floor`` places, those that read within the
        last :meth:`twins`' band and are not yet screened (as :meth:`next_round` gives them); the
        models marked floored, the places screened."""
        self.floored[group] = True
        pick = np.isin(self.floor.model, group) & (self.floor.distance <= self.reach)
        keys, ranked = self._keys(self.floor)[pick], self._keys(self.ranked)
        fresh = ~np.isin(keys, ranked[self.done])
        self.done |= np.isin(ranked, keys)
        self._left = np.bincount(self.ranked.model[~self.done], minlength=len(self._left))
        return self._spots(*(a[pick][fresh] for a in (self.floor.model, self.floor.vertex, self.floor.sign)))

    @staticmethod
    def _spots(model, vertex, sign) -> dict[int, dict[int, np.ndarray]]:
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

