"""The index's one pass over its table (numba; cached, no fastmath): every row's distance to a touch's
rings, the least over the touch's normals (:meth:`tactrec.index.PlaceIndex.ranked`).

Each row's distance is its squared differences on the features the touch reaches, summed in the
features' order in double precision, so it is the same on every CPU and the same as numpy's
column-by-column sum; rows are independent, so the pass runs on every core.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..compiled import fork_safe

__all__ = ["ring_distances"]

fork_safe()


@njit(cache=True, parallel=True)
def ring_distances(features, rows, wanted, signs, best, side):
    """For each of ``rows`` (into ``features (P, F)`` float32), into ``best`` and ``side``: the least
    over the touch's normals ``i`` of ``sum_j (features[row, j] - wanted[i, j])^2`` over the ``j``
    where ``wanted[i, j]`` is finite, and the sign ``signs[i]`` of the normal that gave it (the first
    of equal ones; NaN propagates as ``np.minimum`` does)."""
    for k in prange(len(rows)):
        r = rows[k]
        b = np.inf
        s = np.int8(1)
        for i in range(wanted.shape[0]):
            acc = 0.0
            for j in range(wanted.shape[1]):
                w = wanted[i, j]
                if np.isfinite(w):
                    diff = np.float64(features[r, j]) - w
                    acc += diff * diff
            if acc < b:
                b = acc
                s = signs[i]
            elif acc != acc:
                b = acc
        best[k] = b
        side[k] = s
