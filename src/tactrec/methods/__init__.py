"""Recognition methods, by name: ``paper`` (the paper's algorithm) and ``fast`` (the default).

A method is one object with the hooks of :class:`~tactrec.methods.base.Method`;
a new one adds its module and one line in :data:`METHODS`.
"""

from __future__ import annotations

from ..errors import InputError
from .base import Config, Method, Runner, SearchOutcome
from .fast import FastConfig, FastMethod, Tier
from .paper import PaperConfig, PaperMethod

__all__ = ["METHODS", "DEFAULT_METHOD", "get_method", "Method", "Config", "Runner", "SearchOutcome", "FastConfig",
           "FastMethod", "PaperConfig", "PaperMethod", "Tier"]

METHODS: dict[str, Method] = {
    "paper": PaperMethod(),
    "fast": FastMethod(),
}

DEFAULT_METHOD = "fast"


def get_method(name: str) -> Method:
    """The method called ``name`` (an :class:`InputError` naming the choices if there is none)."""
    if name not in METHODS:
        raise InputError(f"unknown method {name!r}; available: {', '.join(METHODS)}", "--method")
    return METHODS[name]
