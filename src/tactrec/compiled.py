"""What every compiled kernel of the package shares: numba's threading layer.

The kernels (:mod:`tactrec.surfaces.field_kernels`, :mod:`tactrec.surfaces.field_raster`,
:mod:`tactrec.registration.step`, :mod:`tactrec.registration.anderson`, :mod:`tactrec.registration.closedform_paper`,
:mod:`tactrec.surfaces.table_kernels`,
:mod:`tactrec.engine.kernels`, :mod:`tactrec.index.kernels`)
are compiled by numba, cached on disk, without ``fastmath``.  A
:class:`~tactrec.recognition.Recognizer` forks its worker processes after its kernels ran once,
and GNU OpenMP, one of numba's default threading layers, ends a process forked after it ran.  So
before any of them compiles, :func:`fork_safe` selects numba's own scheduler, ``workqueue`` (always
present, safe across a fork), unless the user chose a layer (``NUMBA_THREADING_LAYER``).  It is the
one setting the package makes of another library's state, and each kernel module calls it before it
defines a kernel.
"""

from __future__ import annotations

__all__ = ["fork_safe"]


def fork_safe() -> None:
    """Select numba's ``workqueue`` threading layer unless one was chosen (module text)."""
    from numba import config

    if config.THREADING_LAYER == "default":
        config.THREADING_LAYER = "workqueue"
