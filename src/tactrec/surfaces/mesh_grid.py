"""A mesh's vertices on a grid: the cell each lies in, and the first vertex of each cell (the places
the search and the index of places thin a mesh's vertices to)."""

from __future__ import annotations

import numpy as np

__all__ = ["cells", "grid_keys", "first_per_cell"]


def cells(model, vertices: np.ndarray, size: float) -> np.ndarray:
    """The cell of a grid ``size`` across each of ``vertices (n,)`` lies in, as one integer each."""
    return grid_keys(model.vertices[vertices], model.bounds[0], model.bounds[1], size)


def grid_keys(points: np.ndarray, low: np.ndarray, high: np.ndarray, size: float) -> np.ndarray:
    """The cell of a grid ``size`` across, from ``low`` to ``high``, each of ``points (n, 3)`` lies in, as
    one integer each."""
    span = np.floor((high - low) / size).astype(np.int64) + 1
    cell = np.floor((points - low) / size).astype(np.int64)
    return (cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2]


def first_per_cell(model, order: np.ndarray, size: float) -> np.ndarray:
    """Of the vertices ``order (n,)``, the first of each cell of a grid ``size`` across, in that order."""
    _, first = np.unique(cells(model, order, size), return_index=True)
    return order[np.sort(first)]
