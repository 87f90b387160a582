"""Errors raised at the boundary of tactrec.

Every problem with a user's input (a file, an argument, a database) is an
:class:`InputError`.  Its message is one line that names the file (or the
argument) and what is wrong with it; the command line prints exactly that line
and exits with status 2.

A search spread over a cluster's workers (``--cluster``) that cannot reach some models' files on any
worker raises :class:`ShardsUnavailable`, naming those models: a result never silently leaves them
out.
"""

from __future__ import annotations

import os

__all__ = ["InputError", "ShardsUnavailable"]


class InputError(ValueError):
    """Bad input: a malformed file, an impossible argument, a corrupt database.

    Parameters
    ----------
    message : str
        What is wrong, in one line.
    source : str or os.PathLike, optional
        The file (or argument) the problem was found in.  It leads the message.
    """

    def __init__(self, message: str, source: str | os.PathLike | None = None):
        self.source = None if source is None else os.fspath(source)
        self.reason = " ".join(str(message).split())
        text = self.reason if self.source is None else f"{self.source}: {self.reason}"
        super().__init__(text)


class ShardsUnavailable(RuntimeError):
    """Models whose shards (their database files, held on a cluster's workers) could not answer:
    every worker that held them was lost, or a task on them kept killing its worker.

    Parameters
    ----------
    models : sequence of str
        The models' names, in the database's order.
    reason : str
        Why, in a few words.
    doing : str
        What could not be done with them: ``"searched"``, or ``"built"`` (``tactrec build --cluster``).
    """

    def __init__(self, models, reason: str, *, doing: str = "searched"):
        self.models = list(models)
        self.reason = " ".join(str(reason).split())
        shown = ", ".join(self.models[:10]) + (f" and {len(self.models) - 10} more" if len(self.models) > 10 else "")
        super().__init__(f"{len(self.models)} model{'s' if len(self.models) != 1 else ''} could not be "
                         f"{doing} on the cluster ({self.reason}): {shown}")
