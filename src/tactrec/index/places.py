"""One index over every model's places (:class:`PlaceIndex`): the catalogue's places nearest a touch's
rings, best first, whatever the model.

Each mesh's places and their rings (:mod:`tactrec.surfaces.mesh_rings`) are one row each of one table.  A
touch's rings, for each normal it may have, are compared with every row on the features the touch
reaches (squared differences, summed); the rows are ranked by the least of those over the normals.
The work per touch is one pass over the table (:mod:`.kernels`, on every core), about a tenth of a
second for the five million places of a thousand meshes, against the field screen's work on every
model's places.  Near-equal distances are ordered by row (:func:`tactrec.linalg.stable_order`), so
the ranking is the same on every CPU.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..linalg import stable_prefix
from ..surfaces.mesh_rings import FEATURES, touch_rings

__all__ = ["PlaceIndex", "Ranked"]


@dataclasses.dataclass(frozen=True)
class Ranked:
    """Places of the catalogue, best first: each one's model (an index into the catalogue's models),
    vertex, the side of the normal it matched (1 as estimated, -1 reversed) and its distance."""

    model: np.ndarray
    vertex: np.ndarray
    sign: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return len(self.model)


class PlaceIndex:
    """The places of the meshes among ``models`` (entries with ``.model``; others hold none), their
    models' indices and their rings, in one table."""

    def __init__(self, models):
        owner, vertex, features = [], [], []
        for i, entry in enumerate(models):
            if entry.model.kind != "mesh":
                continue
            rings = entry.model.place_rings
            owner.append(np.full(len(rings.places), i, dtype=np.int32))
            vertex.append(rings.places)
            features.append(rings.features)
        self.owner = np.concatenate(owner) if owner else np.zeros(0, dtype=np.int32)
        self.vertex = np.concatenate(vertex) if vertex else np.zeros(0, dtype=np.int64)
        self.features = np.concatenate(features) if features else np.zeros((0, FEATURES), dtype=np.float32)
        self._ranked: dict = {}                 # the last touch's rankings

    def __len__(self) -> int:
        return len(self.owner)

    @staticmethod
    def reads(touch) -> bool:
        """Whether ``touch``'s curves reach at least one ring (else the index cannot rank for it)."""
        return bool(np.any(np.isfinite(touch_rings(touch, 1))))

    def _distances(self, touch, among) -> tuple:
        """The rows of the models ``among`` (each model's contiguous, in the table's order), each
        one's distance to ``touch``'s rings and side of the normal (the least over the touch's
        :attr:`~tactrec.features.Touch.sides`); kept for the touch."""
        from .kernels import ring_distances                 # numba: only once a touch is ranked

        chosen = np.asarray(sorted(among), dtype=np.int64)
        key = (touch.key, chosen.tobytes())
        if key not in self._ranked:
            # each model's rows are contiguous and the table is in the models' order
            start, end = np.searchsorted(self.owner, chosen, "left"), np.searchsorted(self.owner, chosen, "right")
            size = end - start
            before = np.cumsum(size) - size                   # rows of the chosen models before each
            rows = np.repeat(start - before, size) + np.arange(int(size.sum()), dtype=np.int64)
            signs = np.array([sign for sign, _ in touch.sides], dtype=np.int8)
            wanted = np.array([touch_rings(touch, int(sign)) for sign in signs], dtype=np.float64).reshape(-1, FEATURES)
            best, side = np.empty(len(rows)), np.empty(len(rows), dtype=np.int8)
            ring_distances(self.features, rows, wanted, signs, best, side)
            self._ranked = {key: (rows, best, side)}
        return self._ranked[key]

    def _of(self, rows, best, side, order) -> Ranked:
        r = rows[order]
        return Ranked(self.owner[r].astype(np.int64), self.vertex[r], side[order].astype(np.int64), best[order])

    @staticmethod
    def _first(best: np.ndarray, count: int) -> np.ndarray:
        """``stable_order(best)[:count]``, without sorting the rest (:func:`tactrec.linalg.stable_prefix`)."""
        return stable_prefix(best, count)[:count] if count >= 1 and len(best) else np.zeros(0, dtype=np.int64)

    def ranked(self, touch, among, count: int) -> Ranked:
        """The ``count`` places of the models ``among`` (indices) nearest ``touch``'s rings, best
        first, over the normals the touch may have (:attr:`~tactrec.features.Touch.sides`)."""
        rows, best, side = self._distances(touch, among)
        return self._of(rows, best, side, self._first(best, int(count)))

    def band(self, touch, among, model: int, vertices: np.ndarray) -> float:
        """The median distance to ``touch``'s rings of model ``model``'s places at ``vertices`` (of
        the models ``among``; -inf where none of them is a place)."""
        rows, best, _ = self._distances(touch, among)
        mine = np.flatnonzero(self.owner[rows] == model)
        chosen = mine[np.isin(self.vertex[rows[mine]], vertices)]
        return float(np.median(best[chosen])) if len(chosen) else -np.inf

    def each_best(self, touch, among, count: int) -> Ranked:
        """Each model's own ``count`` places nearest ``touch``'s rings (of the models ``among``), by
        model, each model's best first: the ranking's order within each model, which a band of
        near-equal distances orders by row alone."""
        rows, best, side = self._distances(touch, among)
        owner = self.owner[rows]
        start = np.r_[0, np.flatnonzero(np.diff(owner)) + 1]
        ends = np.r_[start[1:], len(rows)]
        order = [a + self._first(best[a:b], int(count)) for a, b in zip(start, ends) if b > a]
        return self._of(rows, best, side, np.concatenate(order) if order else np.zeros(0, dtype=np.int64))
