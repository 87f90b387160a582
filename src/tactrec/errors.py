"""Errors raised at the boundary of tactrec.

Every problem with a user's input (a file, an argument, a database) is an
:class:`InputError`.  Its message is one line that names the file (or the
argument) and what is wrong with it; the command line prints exactly that line
and exits with status 2.
"""

from __future__ import annotations

import os

__all__ = ["InputError"]


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
