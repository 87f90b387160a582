"""Curvature lookup tables and candidate locations (paper Section 3.2.1).

A table holds ``(k1, k2)`` at many surface points of one model; the candidates
for an estimate ``(k1, k2)`` are the rows within ``delta`` of it (eq. 7),
found with a KD-tree over the curvature plane.
"""

from __future__ import annotations

import dataclasses
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from .surfaces.base import TableSamples

__all__ = ["CurvatureTable"]


@dataclasses.dataclass(frozen=True)
class CurvatureTable:
    """A model's lookup table: rows of :class:`TableSamples` plus a KD-tree."""

    samples: TableSamples

    @cached_property
    def _tree(self) -> cKDTree:
        return cKDTree(np.stack([self.samples.k1, self.samples.k2], axis=1))

    def __len__(self) -> int:
        return len(self.samples)

    def candidates(self, k1: float, k2: float, delta: float) -> np.ndarray:
        """Rows with ``sqrt((k1 - k1_i)^2 + (k2 - k2_i)^2) < delta`` (eq. 7), sorted."""
        idx = self._tree.query_ball_point([k1, k2], r=delta)
        idx = np.asarray(sorted(idx), dtype=np.intp)
        if len(idx):
            d = np.hypot(self.samples.k1[idx] - k1, self.samples.k2[idx] - k2)
            idx = idx[d < delta]
        return idx

    def nearest(self, k1: float, k2: float, count: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``count`` rows nearest in curvature, and their distances."""
        count = min(count, len(self))
        d, idx = self._tree.query([k1, k2], k=count)
        return np.atleast_1d(idx), np.atleast_1d(d)

    def to_arrays(self) -> dict[str, np.ndarray]:
        s = self.samples
        return {"table_sites": s.sites, "table_positions": s.positions, "table_normals": s.normals,
                "table_k1": s.k1, "table_k2": s.k2}

    @classmethod
    def from_arrays(cls, arrays) -> "CurvatureTable":
        return cls(TableSamples(*(np.asarray(arrays[f"table_{k}"], dtype=np.float64)
                                  for k in ("sites", "positions", "normals", "k1", "k2"))))
