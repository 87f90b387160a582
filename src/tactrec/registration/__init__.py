"""Registration of data curves onto models (paper Sections 3.2.2, 4.2, 5.3).

:data:`METHODS` maps a method name and a model kind to a registration
function ``register(model, table, geometry, points, **options) ->
Registration``.  A new method or model kind adds its module and one line here.

``paper`` is the paper's method (lookup within ``delta``, steepest descent,
greedy mesh walk); ``fast`` (the default) ranks candidates instead of
cutting them, and refines poses in six degrees of freedom.  A method may
also offer ``polish(model, registration, geometry, points)``, which
:func:`tactrec.recognition.recognize` applies to the best few models, a
``widen`` (a wider search on the best few when the best fits only loosely),
a ``rescue`` (a wider search when no model fits) and a ``promise`` (the order
in which to register the models).
"""

from __future__ import annotations

from typing import Callable

from ..errors import InputError
from . import closedform_fast, closedform_paper, mesh_fast, mesh_paper
from .result import Registration, local_frame

__all__ = ["METHODS", "DEFAULT_METHOD", "Registration", "local_frame", "get_registrar", "get_polisher", "get_promise",
           "get_rescuer", "get_widener", "method_defaults"]

METHODS: dict[str, dict[str, Callable[..., Registration]]] = {
    "paper": {"closed-form": closedform_paper.register, "mesh": mesh_paper.register},
    "fast": {"closed-form": closedform_fast.register, "mesh": mesh_fast.register},
}

#: per method and model kind, the optional refinement of a finished registration
POLISHERS: dict[str, dict[str, Callable[..., Registration]]] = {
    "fast": {"closed-form": closedform_fast.polish, "mesh": mesh_fast.polish},
}

#: per method and model kind, the optional wider search for touches the best models fit only loosely:
#: ``(scope(errors, geometry, points, *, noise) -> int, widen(model, table, geometry, points, *, curves,
#: bound) -> Registration, revisit(cheap, best) -> bool)``; recognition first registers again, without
#: the bound, the models pruned with a cheap score ``revisit`` accepts, then runs ``widen`` on the
#: ``scope`` best-ranked models
WIDENERS: dict[str, dict[str, tuple[Callable[..., int], Callable[..., Registration], Callable[..., bool]]]] = {
    "fast": {"mesh": (mesh_fast.widen_scope, mesh_fast.widen, mesh_fast.revisit)},
}

#: per method and model kind, the optional wider search for touches no model fits: ``(needed(bound,
#: geometry, points) -> bool, rescue(model, table, geometry, points, *, curves, bound) -> Registration)``;
#: recognition runs ``rescue`` on every model when ``needed`` says the best error ``bound`` is no fit
RESCUERS: dict[str, dict[str, tuple[Callable[..., bool], Callable[..., Registration]]]] = {
    "fast": {"mesh": (mesh_fast.needs_rescue, mesh_fast.rescue)},
}

#: per method and model kind, the optional ``promise(model, geometry, points) -> float`` (lower is
#: more promising) by which recognition orders the models
PROMISES: dict[str, dict[str, Callable[..., float]]] = {
    "fast": {"mesh": mesh_fast.promise},
}

#: per method and model kind, the default options (e.g. the lookup tolerance)
DEFAULTS: dict[str, dict[str, dict]] = {
    "paper": {"closed-form": closedform_paper.DEFAULTS, "mesh": mesh_paper.DEFAULTS},
    "fast": {"closed-form": closedform_fast.DEFAULTS, "mesh": mesh_fast.DEFAULTS},
}

DEFAULT_METHOD = "fast"


def get_registrar(method: str, kind: str) -> Callable[..., Registration]:
    """The registration function of ``method`` for models of ``kind``."""
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; available: {', '.join(METHODS)}", "--method")
    by_kind = METHODS[method]
    if kind not in by_kind:
        raise InputError(f"method {method!r} cannot register onto {kind} models yet "
                         f"(it handles: {', '.join(by_kind)})", "--method")
    return by_kind[kind]


def get_polisher(method: str, kind: str) -> Callable[..., Registration] | None:
    """``method``'s refinement of a finished registration on ``kind`` models, if it has one."""
    return POLISHERS.get(method, {}).get(kind)


def get_rescuer(method: str, kind: str) -> tuple[Callable[..., bool], Callable[..., Registration]] | None:
    """``method``'s wider search on ``kind`` models for touches nothing fits, if it has one:
    ``(needed, rescue)``."""
    return RESCUERS.get(method, {}).get(kind)


def get_widener(method: str, kind: str) -> tuple[Callable[..., int], Callable[..., Registration],
                                                Callable[..., bool]] | None:
    """``method``'s wider search on ``kind`` models for touches the best fit loosely, if it has one:
    ``(scope, widen, revisit)``."""
    return WIDENERS.get(method, {}).get(kind)


def get_promise(method: str, kind: str) -> Callable[..., float] | None:
    """``method``'s measure of how promising a model of ``kind`` is for a touch, if it has one."""
    return PROMISES.get(method, {}).get(kind)


def method_defaults(method: str, kind: str) -> dict:
    return dict(DEFAULTS.get(method, {}).get(kind, {}))
