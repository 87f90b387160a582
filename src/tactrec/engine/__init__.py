"""The hypothesis engine: compiled kernels that score and refine (model, pose) hypotheses on a
mesh's distance field (:mod:`.kernels`), and the breadth generator that feeds them every place and
rotation of a model (:mod:`.screen`).

The kernels are compiled once and cached on disk (numba), without ``fastmath``, and each
hypothesis sums its points in a fixed order: the same bits on every CPU.
"""

from __future__ import annotations

__all__ = ["one_thread"]


def one_thread() -> None:
    """Run the kernels on one thread in this process (a worker process that shares the cores with
    others)."""
    import numba

    numba.set_num_threads(1)
