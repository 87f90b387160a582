"""What runs on a cluster's workers: the shards a worker holds, and the tasks the client sends.

A worker keeps its shards in :class:`ShardPlugin`, a ``distributed.WorkerPlugin`` registered once
on every worker (and on every worker that joins later).  A catalogue (one database's models, with
the method and tips they are prepared for) is a :class:`~tactrec.runner.Held` whose ``entries``
load each model from its database file the first time a stage reads it (:class:`Shards`), prepare
it for the method, and keep it for as long as a client uses the catalogue.
"""

from __future__ import annotations

import resource
import threading
from pathlib import Path

from distributed import WorkerPlugin, get_worker

from ..errors import InputError
from ..runner import Held

__all__ = ["PLUGIN", "ShardPlugin", "Shards", "run_stage", "load_stage", "release", "stored_blob", "peak_mb"]

#: the plugin's name on the workers
PLUGIN = "tactrec-shards"


def _one_thread() -> None:
    from ..engine import one_thread

    one_thread()                 # the workers share the cores; a kernel's own threads would only contend


def _loaded(folder: str, item: dict, method: str, tips: tuple):
    """The model of the index entry ``item`` of the database ``folder``, prepared for ``method`` and
    the tip radii ``tips`` as a :class:`~tactrec.recognition.Recognizer` prepares its models."""
    from ..database import _load_entry
    from ..methods import get_method

    if not Path(folder).is_dir():
        raise InputError(f"not readable on the Dask worker {get_worker().address}: the workers load the "
                         "database's files, so each must see the database folder at this path", folder)
    entry = _load_entry(Path(folder), item)
    get_method(method).prepare(entry.model)
    for r in tips if entry.model.kind == "mesh" else ():
        entry.model.offset(float(r)).distance_field
    return entry


class Shards:
    """A catalogue's models on one worker, by their index in the catalogue: ``where[i]`` is model
    ``i``'s ``(folder, index entry)``, told by the client; a model is loaded on first use and kept."""

    def __init__(self, count: int, method: str, tips: tuple):
        self.count, self.method, self.tips = count, method, tips
        self.where: dict[int, tuple] = {}
        self.loaded: dict[int, object] = {}
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return self.count

    def __getitem__(self, i: int):
        entry = self.loaded.get(i)
        if entry is None:
            with self._lock:                    # one load of a model, whatever the worker's threads
                entry = self.loaded.get(i)
                if entry is None:
                    entry = self.loaded[i] = _loaded(*self.where[i], self.method, self.tips)
        return entry


class ShardPlugin(WorkerPlugin):
    """The catalogues a worker holds, each kept while some client's runner (its token) uses it."""

    idempotent = True            # registered once: a second client does not reset the first's shards

    def setup(self, worker) -> None:
        self.catalogues: dict[str, Held] = {}
        self.users: dict[str, set] = {}
        self.lock = threading.Lock()

    def held(self, key: str, count: int, method: str, tips: tuple, token: str) -> Held:
        """The catalogue ``key`` (made empty the first time), now in use by ``token``."""
        with self.lock:
            if key not in self.catalogues:
                held = Held([])
                held.entries = Shards(count, method, tips)
                self.catalogues[key] = held
            self.users.setdefault(key, set()).add(token)
            return self.catalogues[key]

    def release(self, key: str, token: str) -> None:
        """``token`` is done with catalogue ``key``: forgotten when no client uses it."""
        with self.lock:
            users = self.users.get(key, set())
            users.discard(token)
            if not users:
                self.users.pop(key, None)
                self.catalogues.pop(key, None)


def run_stage(spec: tuple, where: dict, stage, indices: list, args: tuple):
    """``stage(held, indices, *args)`` on this worker's catalogue ``spec`` = ``(key, count, method,
    tips, token)``, after adding ``where`` to what it knows of its models' files: ``("ok",
    results)``; ``("missing", None)`` where it does not know where some model of ``indices`` lies
    (a worker that started again at the same address): the client then tells it; ``("bad",
    (reason, source))`` for a model file it cannot read, an :class:`InputError` the client raises
    (an answer, not a failed task the worker would log)."""
    _one_thread()
    held = get_worker().plugins[PLUGIN].held(*spec)
    held.entries.where.update(where)
    if any(i not in held.entries.where for i in indices):
        return "missing", None
    try:
        return "ok", stage(held, indices, *args)
    except InputError as exc:
        return "bad", (exc.reason, exc.source)


def load_stage(held: Held, indices: list) -> list:
    """A stage that loads (and prepares) the models at ``indices`` and answers nothing for each."""
    for i in indices:
        held.entries[i]
    return [None] * len(indices)


def release(key: str, token: str, dask_worker=None) -> None:
    """Run on every worker (``Client.run``) when a runner closes: :meth:`ShardPlugin.release`."""
    plugin = dask_worker.plugins.get(PLUGIN)
    if plugin is not None:
        plugin.release(key, token)


def stored_blob(model, tips: tuple) -> tuple[bytes, int]:
    """A build's task: the bytes of ``model``'s database file and its table's rows, as a build in
    one process makes them (:func:`tactrec.database._stored_blob`)."""
    from ..database import _stored_blob

    _one_thread()
    return _stored_blob(model, tips)


def peak_mb(dask_worker=None) -> float:
    """This worker process's peak resident memory, MB (``Client.run``)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
