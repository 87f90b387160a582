"""Where a recognition's per-model stages run: in this process, or dealt into fixed shares over
worker processes forked with the models (:class:`~tactrec.recognition.Recognizer`'s ``runner``)."""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Sequence

__all__ = ["default_workers", "workers_for"]


def default_workers() -> int:
    """Worker processes for a :class:`Recognizer`: two where the machine has them."""
    return max(1, min(2, os.cpu_count() or 1))


def workers_for(models) -> int:
    """Worker processes for a command's :class:`Recognizer` over ``models``: :func:`default_workers`
    for more than four, else this process alone."""
    return default_workers() if len(models) > 4 else 1


class _Held:
    """The models a process holds, a cache the stages may keep per touch, and what they build once
    per model (``samples``)."""

    def __init__(self, entries: Sequence):
        self.entries = list(entries)
        self.cache: dict = {}
        self.samples: dict = {}


class _Serial:
    """Runs a stage in this process."""

    def __init__(self, held: _Held):
        self.held = held

    def map(self, stage, indices, *args, items=None) -> list:
        if items is None:
            return stage(self.held, list(indices), *args)
        return stage(self.held, list(indices), *args, list(items))


_WORKER: list = []            # in a worker process only: the models it was forked with (the pool's initializer)


def _start_worker(held: _Held) -> None:
    _WORKER[:] = [held]
    from .engine import one_thread

    one_thread()                 # the processes share the cores; a kernel's own threads would only contend


def _in_worker(stage, indices, *args) -> list:
    return stage(_WORKER[0], indices, *args)


class _Pool:
    """Runs a stage over the models dealt into fixed shares (every ``n``-th model of a call), one
    share a worker process: the result does not depend on the number of workers or on scheduling.

    Processes, not threads: the exact closest-point queries hold Python's global lock."""

    def __init__(self, held: _Held, workers: int):
        self.held = held
        self.workers = workers
        self.pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"),
                                        initializer=_start_worker, initargs=(held,))

    def map(self, stage, indices, *args, items=None) -> list:
        indices = list(indices)
        if self.pool is None or len(indices) < 2:
            return _Serial(self.held).map(stage, indices, *args, items=items)
        n = self.workers
        shares = [(indices[k::n],) + (() if items is None else (list(items)[k::n],)) for k in range(n)]
        try:
            futures = [self.pool.submit(_in_worker, stage, share[0], *args, *share[1:]) for share in shares if share[0]]
            parts = [f.result() for f in futures]
        except BrokenProcessPool:                    # a worker died (e.g. out of memory): go on without
            self.pool = None
            return _Serial(self.held).map(stage, indices, *args, items=items)
        out = [None] * len(indices)
        for k, part in enumerate(parts):
            out[k::self.workers] = part
        return out

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()
            self.pool = None
