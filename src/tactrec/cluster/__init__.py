"""Dask for more than one machine: ``--cluster ADDRESS`` or ``--cluster local:N``.

:func:`connect` opens a :class:`Cluster`: a Dask scheduler's address, or ``local:N``, a cluster of
``N`` worker processes on this machine, started and ended with it.  A
:class:`~tactrec.recognition.Recognizer` given it (``cluster=``) runs its stages on the workers
(:class:`.runner.ClusterRunner`: the database's per-model files are the shards, each loaded once
onto a worker and kept there), and :func:`tactrec.database.build_database` given it builds the
models as tasks (:mod:`.build`).  Answers and databases are the same as without it, to the byte.

The workers read the database's files themselves, so each must see the database folder at the same
path as the client (a shared or copied folder), and must import the same tactrec.  This package,
and Dask with it, is imported only where ``--cluster`` is given.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading

from distributed import Client, LocalCluster

from ..errors import InputError
from .worker import PLUGIN, ShardPlugin, peak_mb

__all__ = ["connect", "Cluster", "TIMEOUT", "WAIT_WORKERS"]

#: seconds to reach a scheduler
TIMEOUT = 2.0
#: seconds to wait for a scheduler's first worker
WAIT_WORKERS = 10.0


class Cluster:
    """A connected Dask cluster (:func:`connect`): its ``client``, and the local cluster it started,
    if any (``local:N``), ended by :meth:`close` or the ``with`` block."""

    def __init__(self, client: Client, address: str, local: LocalCluster | None = None):
        self.client, self.address, self.local = client, address, local

    def __enter__(self) -> "Cluster":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def workers(self) -> list[str]:
        """The workers' addresses, sorted."""
        return sorted(self.client.nthreads())

    def runner(self, entries, *, method: str, tips=()):
        """A :class:`.runner.ClusterRunner` over ``entries`` (a :class:`~tactrec.recognition.Recognizer`'s)."""
        from .runner import ClusterRunner

        return ClusterRunner(self, entries, method=method, tips=tips)

    def stored(self, models: list, todo: list[int], *, quiet: bool, tips=()):
        """The models ``todo`` built on the workers (:func:`.build.stored`), for a database build."""
        from .build import stored

        return stored(self.client, models, todo, quiet=quiet, tips=tips)

    def peak_mb(self) -> dict[str, float]:
        """Each worker's peak resident memory so far, MB, by address."""
        return dict(sorted(self.client.run(peak_mb).items()))

    def close(self) -> None:
        self.client.close()
        if self.local is not None:
            self.local.close()


def _unstarted(error: BaseException) -> Client | None:
    """The client whose start raised ``error`` (found in its traceback), to be closed at once: left
    to the collector, it would take seconds to time out and print a traceback as it goes."""
    tb, found = error.__traceback__, None
    while tb is not None:
        candidate = tb.tb_frame.f_locals.get("self")
        found = candidate if isinstance(candidate, Client) else found
        tb = tb.tb_next
    return found


def _answers(address: str) -> None:
    """Refuse an address where no Dask scheduler answers within about :data:`TIMEOUT` seconds: Dask's own
    connection and handshake, under a deadline (on its own it waits without end for a server that
    accepts a connection and says nothing, as a web server does)."""
    from distributed.comm import connect as dask_connect

    async def handshake():
        comm = await asyncio.wait_for(dask_connect(address, timeout=TIMEOUT), 2 * TIMEOUT)
        comm.abort()

    failed: list = []

    def run():
        try:
            asyncio.run(handshake())
        except BaseException as exc:              # noqa: BLE001 -- odd servers give MemoryError, refusals OSError
            failed.append(exc)

    thread = threading.Thread(target=run, name="tactrec-probe", daemon=True)
    thread.start()
    thread.join(3 * TIMEOUT)
    if thread.is_alive() or (failed and isinstance(failed[0], TimeoutError) and not str(failed[0])):
        raise InputError(f"no Dask scheduler answered within {2 * TIMEOUT:g} s", address)
    if failed:
        reason = " ".join(str(failed[0]).split())[:200]
        raise InputError(f"cannot reach a Dask scheduler ({type(failed[0]).__name__}: {reason})", address)


def _local(text: str, address: str) -> tuple[Client, LocalCluster]:
    if not text.isdigit() or int(text) < 1:
        raise InputError("local:N takes a whole number of workers N, at least 1", address)
    try:
        local = LocalCluster(n_workers=int(text), threads_per_worker=1, processes=True, host="127.0.0.1",
                             dashboard_address=None, silence_logs=logging.ERROR)
    except Exception as exc:                      # noqa: BLE001 -- whatever stopped the workers starting
        raise InputError(f"cannot start a local Dask cluster ({type(exc).__name__}: {exc})", address) from None
    return Client(local, set_as_default=False), local


def connect(address: str) -> Cluster:
    """The cluster at ``address``: ``local:N`` starts ``N`` worker processes here (one thread each);
    any other address is a Dask scheduler's (``tcp://host:port``).  One that cannot be reached, or
    that has no worker within :data:`WAIT_WORKERS` seconds, is an :class:`InputError` naming it."""
    local = None
    if address.startswith("local:"):
        client, local = _local(address[len("local:"):], address)
    else:
        _answers(address)
        failure, client = None, None
        try:
            client = Client(address, timeout=TIMEOUT, set_as_default=False)
        except Exception as exc:                  # noqa: BLE001 -- odd servers give MemoryError, refusals OSError
            failure = f"cannot reach a Dask scheduler ({type(exc).__name__}: {' '.join(str(exc).split())[:200]})"
            unstarted = _unstarted(exc)
            if unstarted is not None:
                with contextlib.suppress(Exception):
                    unstarted.close(timeout=TIMEOUT)
        if failure is not None:
            raise InputError(failure, address)
    cluster = Cluster(client, address, local)
    try:
        client.wait_for_workers(1, timeout=WAIT_WORKERS)
    except Exception:                             # noqa: BLE001 -- a timeout, or the scheduler gone meanwhile
        cluster.close()
        raise InputError(f"the Dask scheduler has no worker (waited {WAIT_WORKERS:g} s)", address) from None
    try:
        client.register_plugin(ShardPlugin(), name=PLUGIN)
    except Exception as exc:                      # noqa: BLE001 -- a worker that cannot unpickle or set it up
        cluster.close()
        raise InputError(f"the Dask workers cannot hold tactrec's shards ({type(exc).__name__}: "
                         f"{' '.join(str(exc).split())[:200]}); each must import the same tactrec", address) from None
    return cluster
