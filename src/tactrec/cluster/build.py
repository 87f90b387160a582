"""``tactrec build --cluster``: the models built as tasks on a cluster's workers (:func:`stored`).

Each task makes the bytes of one model's database file (:func:`tactrec.database._stored_blob`, the
function a build in one process runs); the client writes them through the build's own atomic and
resumable path, so the database is the same, file for file and byte for byte.  A worker lost
mid-build has its models built again on the others (Dask sends them again: a build's tasks go to
any worker); a model whose task kept killing its workers, or a cluster left with no worker, ends
the build with :class:`~tactrec.errors.ShardsUnavailable` naming the models not built, and what
was written is kept for the next build.
"""

from __future__ import annotations

from distributed import wait
from distributed.scheduler import KilledWorker

from ..errors import ShardsUnavailable
from .worker import stored_blob

__all__ = ["stored", "IN_FLIGHT"]

#: tasks in flight per worker (each holds its model until it is built)
IN_FLIGHT = 2


def stored(client, models: list, todo: list[int], *, quiet: bool, tips=(), poll: float = 0.25):
    """``(k, blob, rows)`` for each model ``k`` of ``todo``, as each is built on ``client``'s
    workers (in the order they finish): the generator :func:`tactrec.database.build_database`
    writes from."""
    from ..database import _progress

    queue = list(todo)
    pending: dict = {}
    bar = _progress(range(len(todo)), total=len(todo), desc="building", quiet=quiet)
    try:
        while queue or pending:
            workers = len(client.nthreads())
            if not workers:
                raise ShardsUnavailable([models[k].name for k in sorted(set(queue) | set(pending.values()))],
                                        "no worker is left on the cluster", doing="built")
            while queue and len(pending) < IN_FLIGHT * workers:
                k = queue.pop(0)
                pending[client.submit(stored_blob, models[k], tuple(tips), pure=False)] = k
            try:
                with client.as_current():                 # the futures' own client, not a default one
                    done = wait(list(pending), timeout=poll, return_when="FIRST_COMPLETED").done
            except TimeoutError:
                continue
            for future in sorted(done, key=pending.get):
                k = pending.pop(future)
                if future.status == "error" and isinstance(future.exception(), KilledWorker):
                    raise ShardsUnavailable([models[k].name], "its task ended every worker it ran on", doing="built")
                if future.status == "cancelled":
                    queue.insert(0, k)
                    continue
                blob, rows = future.result()
                yield k, blob, rows
                bar.update()
    finally:
        for future in pending:
            future.cancel()
        bar.close()
