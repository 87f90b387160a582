"""The hypothesis engine: compiled kernels that score and refine (model, pose) hypotheses on a
mesh's distance field (:mod:`.kernels`), and the breadth generator that feeds them every place and
rotation of a model (:mod:`.screen`).

The kernels are compiled once and cached on disk (numba), without ``fastmath``, and each
hypothesis sums its points in a fixed order: the same bits on every CPU.  numba is imported with
:mod:`.kernels`, when a search first screens on a field; ``tactrec recognize`` loads them in the
background while it reads its database (:func:`preload`), so that a one-off command's search does
not wait for them.
"""

from __future__ import annotations

import threading

__all__ = ["one_thread", "preload", "LOOKUP_COST"]

#: one field lookup, in closest-point queries (a search's budget unit): measured 1.2 M exact
#: queries and 50-100 M lookups a second on this package's benchmark machine
LOOKUP_COST = 1.0 / 50.0


def preload() -> threading.Thread:
    """Start loading the compiled kernels (numba's import and its cached code, about half a second)
    in a background thread, so that a one-off command overlaps it with reading its database: join
    the thread before any kernel runs or any process is forked.  A failure is left for the first
    real call to report."""
    def load():
        try:
            from .kernels import warm

            warm()
        except Exception:                     # noqa: BLE001 -- the search's own call reports it
            pass

    thread = threading.Thread(target=load, name="tactrec-kernels", daemon=True)
    thread.start()
    return thread


def one_thread() -> None:
    """Run the kernels on one thread in this process (a worker process that shares the cores with
    others)."""
    import numba

    numba.set_num_threads(1)
