"""A recognition's per-model stages on a cluster's workers, with :class:`~tactrec.runner.Pool`'s
``map``: :class:`ClusterRunner`.

The shards are the database's per-model files.  Model ``k`` of the catalogue is dealt to worker
``k mod n`` of the ``n`` workers (their addresses sorted), which loads it on first use and keeps it
(:mod:`.worker`).  A stage called on some models goes as one task to each worker that holds any
of them, restricted to that worker; the answers are put back in the order of the models asked for.
A model's stage answers the same bytes in any process (nothing on the path from a touch to a result
depends on the BLAS or on threads), so the ranking is that of one process, bit for bit.

The runner watches its tasks itself: a worker that leaves the cluster (killed, out of memory, its
machine lost) has its models dealt again over the workers left, which load them, and its tasks are
sent again.  Where no worker is left, or a task kept killing the workers it ran on, the stage raises
:class:`~tactrec.errors.ShardsUnavailable` naming the models it could not answer: a result never
leaves a model out silently.
"""

from __future__ import annotations

import hashlib
import json
import uuid
from pathlib import Path

from distributed import wait
from distributed.scheduler import KilledWorker

from ..errors import InputError, ShardsUnavailable
from .worker import load_stage, release, run_stage

__all__ = ["ClusterRunner", "POLL", "GATHER"]

#: seconds between two looks at which workers are alive, while a stage's tasks run
POLL = 0.25
#: seconds a finished task's answer may take to arrive before its worker is looked at again
GATHER = 5.0


def shard_of(entry) -> tuple[str, dict]:
    """Where ``entry``'s model lies: its database folder (as an absolute path, which the workers must
    see) and index entry; one built in memory (not loaded from a database) is an :class:`InputError`:
    a cluster's workers read the files."""
    if entry.stored is None:
        raise InputError("not loaded from a database: a cluster's workers load the models from the database's "
                         "files (build one with 'tactrec build' and give --db)", entry.name)
    folder, item = entry.stored
    return str(Path(folder).resolve()), item


class ClusterRunner:
    """Runs a stage over ``entries`` (:class:`~tactrec.recognition.ModelEntry`, each loaded from a
    database) on ``cluster``'s workers (the module text), each model prepared there for ``method``
    and the tip radii ``tips``.  Every worker loads its shards when the runner starts."""

    def __init__(self, cluster, entries, *, method: str, tips=()):
        self.cluster = cluster
        self.client = cluster.client
        self.where = [shard_of(e) for e in entries]
        self.names = [e.name for e in entries]
        tips = tuple(float(r) for r in tips)
        digest = hashlib.sha256(json.dumps([[folder, item["file"], item["file_sha256"]] for folder, item in self.where]
                                           + [method, list(tips)]).encode()).hexdigest()
        self.spec = (digest, len(self.where), method, tips, uuid.uuid4().hex)
        self.told: dict[str, set] = {}               # the models each worker has been told where to find
        alive = self._alive(range(len(self.where)))
        if not alive:
            raise ShardsUnavailable(self.names, "the cluster has no worker")
        self.owner = [alive[k % len(alive)] for k in range(len(self.where))]
        self.map(load_stage, range(len(self.where)))

    def _alive(self, unanswered) -> list[str]:
        """The workers' addresses, sorted; a scheduler that stopped answering leaves ``unanswered``
        (the models still waited for) unavailable."""
        try:
            return sorted(self.client.nthreads())
        except Exception as exc:                    # noqa: BLE001 -- whatever the lost connection raised
            raise ShardsUnavailable([self.names[i] for i in sorted(set(unanswered))],
                                    f"the Dask scheduler stopped answering: {type(exc).__name__}") from None

    def _deal_again(self, alive: list[str]) -> None:
        """The models of workers that are gone, dealt in turn over the workers ``alive`` (sorted)."""
        gone = sorted(set(self.owner) - set(alive))
        moved = [k for k, a in enumerate(self.owner) if a in gone]
        for j, k in enumerate(moved):
            self.owner[k] = alive[j % len(alive)]
        for a in gone:
            self.told.pop(a, None)

    def map(self, stage, indices, *args, items=None) -> list:
        """``stage(held, share, *args[, items of the share])`` over the models at ``indices``, each share
        on the worker holding it; one result per index, in order."""
        indices = list(indices)
        items = None if items is None else list(items)
        out: list = [None] * len(indices)
        pending: dict = {}                            # future -> (worker, positions in indices, told now)

        def submit(positions, *, tell_all: bool = False) -> None:
            shares: dict[str, list[int]] = {}
            for p in positions:
                shares.setdefault(self.owner[indices[p]], []).append(p)
            for address, share in sorted(shares.items()):
                models = [indices[p] for p in share]
                told = set() if tell_all else self.told.get(address, set())
                where = {i: self.where[i] for i in models if i not in told}
                extra = () if items is None else ([items[p] for p in share],)
                future = self.client.submit(run_stage, self.spec, where, stage, models, args + extra, pure=False,
                                            workers=[address], allow_other_workers=False)
                pending[future] = (address, share, set(where))

        def unanswered() -> list[int]:
            return [indices[p] for _, share, _ in pending.values() for p in share]

        submit(range(len(indices)))
        try:
            while pending:
                try:
                    with self.client.as_current():       # the futures' own client, not a default one
                        done = wait(list(pending), timeout=POLL, return_when="FIRST_COMPLETED").done
                except TimeoutError:
                    done = set()
                again, look = [], not done
                for future in done:
                    address, share, told = pending[future]
                    if future.status == "error":
                        error = future.exception()
                        if isinstance(error, KilledWorker):
                            raise ShardsUnavailable([self.names[indices[p]] for p in share],
                                                    "a task on them ended every worker it ran on")
                        future.result()                   # the stage's own error, raised here
                    if future.status != "finished":      # cancelled, or its answer lost with its worker
                        del pending[future]
                        again += share
                        continue
                    try:
                        status, found = future.result(timeout=GATHER)
                    except TimeoutError:
                        look = True                       # its worker is looked at below
                        continue
                    del pending[future]
                    if status == "missing":                # a worker started again at that address
                        submit(share, tell_all=True)
                        continue
                    if status == "bad":                    # a model file the worker cannot read
                        raise InputError(*found)
                    self.told.setdefault(address, set()).update(told)
                    for p, result in zip(share, found):
                        out[p] = result
                if not (look or again):
                    continue
                alive = self._alive(unanswered() + [indices[p] for p in again])
                lost = [f for f, (address, _, _) in pending.items() if address not in alive]
                if not lost and not again:
                    continue
                for future in lost:
                    again += pending.pop(future)[1]
                    future.cancel()
                if not alive:
                    raise ShardsUnavailable([self.names[i] for i in sorted(set(unanswered())
                                                                           | {indices[p] for p in again})],
                                            "no worker is left on the cluster")
                self._deal_again(alive)
                submit(sorted(again))
        finally:
            for future in pending:
                future.cancel()
        return out

    def close(self) -> None:
        """Tell the workers this runner is done with its shards (each forgets those no client uses)."""
        try:
            self.client.run(release, self.spec[0], self.spec[-1])
        except Exception:                            # noqa: BLE001 -- a cluster already gone holds nothing
            pass
