"""Where a recognition's per-model stages run: in this process, or on worker processes forked with
the models, each of which prepares and runs its own fixed share (:class:`Pool`; the
:class:`~tactrec.recognition.Recognizer`'s ``runner``).

:class:`Workers` is the one pool of the package: processes forked with what they hold (the models,
passed to the process function, not kept in a global), each served over a pipe of its own.  A
worker holds no end of any pipe but its own, so when the process that forked it dies, however it
dies (SIGKILL, the OOM killer), its pipe closes and the worker exits with it.
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
from typing import Callable, Iterable, Sequence

__all__ = ["default_workers", "workers_for", "can_fork", "Workers", "WorkerLost", "Held", "Serial", "Pool"]


def default_workers() -> int:
    """Worker processes for a :class:`Recognizer`: two where the machine has them."""
    return max(1, min(2, os.cpu_count() or 1))


def workers_for(models) -> int:
    """Worker processes for a command's :class:`Recognizer` over ``models``: :func:`default_workers`
    for more than four, else this process alone."""
    return default_workers() if len(models) > 4 else 1


def can_fork() -> bool:
    """Whether this process may fork workers: where ``fork`` exists, and not from inside another
    process's worker (a benchmark running touches in parallel), where forking can deadlock and that
    pool already uses the cores."""
    return "fork" in multiprocessing.get_all_start_methods() and multiprocessing.parent_process() is None


class WorkerLost(RuntimeError):
    """A worker process ended before it answered (out of memory, killed)."""


def _serve(state, conn, foreign, start, rank: int) -> None:
    """A worker's life: close the other pipes' ends inherited with the fork, run ``start(state, rank)``,
    then answer ``(fn, args)`` with ``fn(state, *args)`` until told to stop or the pipe closes."""
    for other in foreign:
        other.close()
    if start is not None:
        start(state, rank)
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):                 # the parent is gone
            return
        if message is None:
            return
        fn, args = message
        try:
            answer = ("ok", fn(state, *args))
        except BaseException as exc:               # noqa: BLE001 -- the caller re-raises it
            answer = ("error", exc)
        try:
            conn.send(answer)
        except Exception as exc:                    # noqa: BLE001 -- an answer that does not pickle
            conn.send(("error", RuntimeError(f"{type(exc).__name__}: {exc}")))


class Workers:
    """``count`` processes forked with ``state``, worker ``k`` running ``start(state, k)`` first (see
    the module text).

    ``fn(state, *args)`` runs in a worker for each of the ``args`` given; exceptions are raised in
    this process; a worker that ends unanswered raises :class:`WorkerLost`, and the pool is closed."""

    def __init__(self, state, count: int, *, start: Callable[[object, int], None] | None = None):
        context = multiprocessing.get_context("fork")
        self._pipes, self._processes = [], []
        for k in range(count):
            mine, theirs = context.Pipe()
            process = context.Process(target=_serve, args=(state, theirs, list(self._pipes) + [mine], start, k),
                                      daemon=True)
            process.start()
            theirs.close()
            self._pipes.append(mine)
            self._processes.append(process)

    def __len__(self) -> int:
        return len(self._pipes)

    @property
    def pids(self) -> list[int]:
        """The workers' process ids."""
        return [p.pid for p in self._processes]

    def _answer(self, k: int):
        try:
            status, value = self._pipes[k].recv()
        except (EOFError, OSError):
            self.close(timeout=0.5)
            raise WorkerLost("a worker process ended before it answered") from None
        if status == "error":
            raise value
        return value

    def each(self, fn: Callable, args: Sequence[tuple | None]) -> list:
        """``fn(state, *args[k])`` in worker ``k`` for each ``k`` whose ``args[k]`` is not None (at most
        one call per worker), all at once; their answers in order (None where nothing was asked)."""
        if len(args) > len(self._pipes):
            raise ValueError(f"{len(args)} calls for {len(self._pipes)} workers")
        try:
            for pipe, a in zip(self._pipes, args):
                if a is not None:
                    pipe.send((fn, tuple(a)))
        except (BrokenPipeError, OSError):
            self.close(timeout=0.5)
            raise WorkerLost("a worker process ended before it was asked") from None
        return [None if a is None else self._answer(k) for k, a in enumerate(args)]

    def map(self, fn: Callable, items: Iterable) -> Iterable:
        """``fn(state, item)`` for each of ``items``, each worker taking the next item when it is done;
        the answers in the items' order, as they come."""
        items = list(items)
        if not self._pipes:
            raise WorkerLost("the pool is closed")
        busy: dict[int, int] = {}
        answers: dict[int, object] = {}
        following = 0
        for k, item in enumerate(items):
            if len(busy) == len(self._pipes):
                done = next(iter(multiprocessing.connection.wait([self._pipes[w] for w in busy])))
                w = self._pipes.index(done)
                answers[busy.pop(w)] = self._answer(w)
            w = next(w for w in range(len(self._pipes)) if w not in busy)
            self._pipes[w].send((fn, (item,)))
            busy[w] = k
            while following in answers:
                yield answers.pop(following)
                following += 1
        while busy:
            done = next(iter(multiprocessing.connection.wait([self._pipes[w] for w in busy])))
            w = self._pipes.index(done)
            answers[busy.pop(w)] = self._answer(w)
            while following in answers:
                yield answers.pop(following)
                following += 1

    def close(self, timeout: float = 5.0) -> None:
        """Tell the workers to stop and wait for them (``timeout`` seconds each, then end them)."""
        for pipe in self._pipes:
            try:
                pipe.send(None)
            except (BrokenPipeError, OSError):
                pass
        for process in self._processes:
            process.join(timeout)
            if process.is_alive():
                process.terminate()
                process.join(timeout)
        for pipe in self._pipes:
            pipe.close()
        self._pipes, self._processes = [], []


class Held:
    """The models a process holds, a cache the stages may keep per touch, and what they build once
    per model (``samples``)."""

    def __init__(self, entries: Sequence):
        self.entries = list(entries)
        self.cache: dict = {}
        self.samples: dict = {}


class Serial:
    """Runs a stage in this process."""

    def __init__(self, held: Held):
        self.held = held

    def map(self, stage, indices, *args, items=None) -> list:
        if items is None:
            return stage(self.held, list(indices), *args)
        return stage(self.held, list(indices), *args, list(items))


def _start(prepare, held: Held, rank: int, count: int) -> None:
    """A worker's start: one thread for its kernels, and its own share of the models prepared."""
    from .engine import one_thread

    one_thread()                 # the processes share the cores; a kernel's own threads would only contend
    for entry in held.entries[rank::count] if prepare is not None else ():
        prepare(entry)


def _ready(held: Held) -> None:
    return None


def _stage(held: Held, stage, indices, args) -> list:
    return stage(held, indices, *args)


class Pool:
    """Runs a stage over the models, each on the worker process that holds it (:class:`Workers`):
    model ``i`` of ``held`` belongs to worker ``i % workers``, which alone prepares it (``prepare``,
    when it starts) and so holds its fields and trees, as a cluster's workers hold their shards.  The
    result does not depend on the number of workers or on scheduling.  Where a worker is lost (out
    of memory, say), it goes on in this process.

    Processes, not threads: the exact closest-point queries hold Python's global lock."""

    def __init__(self, held: Held, workers: int, *, prepare: Callable | None = None):
        self.held = held
        self.workers = workers
        self.pool: Workers | None = Workers(held, workers,
                                            start=lambda state, rank: _start(prepare, state, rank, workers))
        try:
            self.pool.each(_ready, [()] * workers)        # prepared before the first touch, as in one process
        except WorkerLost:
            self.pool = None

    def map(self, stage, indices, *args, items=None) -> list:
        indices = list(indices)
        if self.pool is None or not indices:
            return Serial(self.held).map(stage, indices, *args, items=items)
        items = None if items is None else list(items)
        n = self.workers
        shares = [[p for p, i in enumerate(indices) if i % n == k] for k in range(n)]
        calls = [None if not share else
                 (stage, [indices[p] for p in share], args + (() if items is None else ([items[p] for p in share],)))
                 for share in shares]
        try:
            parts = self.pool.each(_stage, calls)
        except WorkerLost:                           # a worker died (e.g. out of memory): go on without
            self.pool = None
            return Serial(self.held).map(stage, indices, *args, items=items)
        out = [None] * len(indices)
        for share, part in zip(shares, parts):
            for p, found in zip(share, part or ()):
                out[p] = found
        return out

    def close(self) -> None:
        if self.pool is not None:
            self.pool.close()
            self.pool = None
