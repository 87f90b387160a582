"""The ``tactrec`` command's ``--cluster ADDRESS|local:N`` (:mod:`tactrec.cluster`), imported only
where it is given."""

from __future__ import annotations

import contextlib

__all__ = ["add_cluster_option", "opened", "EXIT_UNAVAILABLE"]

#: the exit status of a command some of whose models' shards could not answer on the cluster
EXIT_UNAVAILABLE = 3


def add_cluster_option(p, *, several: bool = False) -> None:
    """``--cluster``; ``several``: a benchmark's, comma-separated addresses, each run beside one process."""
    if several:
        p.add_argument("--cluster", metavar="ADDRESS,...", help="scale-out: also run on these Dask clusters, "
                       "comma-separated (e.g. local:1,local:2), each beside the one process")
        return
    p.add_argument("--cluster", metavar="ADDRESS", help="run on a Dask cluster: a scheduler's address "
                   "(tcp://host:port), or local:N for N worker processes here; the workers read the database's "
                   "files, so each must see its folder at the same path (docs/commands.md)")


@contextlib.contextmanager
def opened(args):
    """The cluster of ``args.cluster`` (None without it), closed after the block."""
    address = getattr(args, "cluster", None)
    if address is None:
        yield None
        return
    import logging

    from .cluster import connect

    logging.getLogger("distributed").setLevel(logging.ERROR)     # Dask's own notices, not the command's output
    with connect(address) as cluster:
        yield cluster
