"""What a recognition method is: one object with named hooks and a frozen, validated config.

A method (:class:`Method`) turns one :class:`~tactrec.features.Touch` and a
list of models into a ranking of :class:`~tactrec.registration.Registration`
results, through these hooks:

* :meth:`Method.configure` -- the method's :class:`Config` from keyword
  options (an unknown or invalid option is an :class:`~tactrec.errors.InputError`);
* :meth:`Method.prepare` -- per-model structures, built once (and kept in
  the worker processes);
* :meth:`Method.search` -- the registrations, given a :class:`Runner` that
  runs a stage over the models in worker processes or in this one (on all
  models, or on a chosen few: ``among``);
* :meth:`Method.refit` -- a search's registrations carried over to nearly the same touch (a few of
  its points set aside or taken back: :func:`tactrec.recognition.again.judge_ends`).

A new method is its own module and one line in :data:`tactrec.methods.METHODS`.
"""

from __future__ import annotations

import dataclasses
import difflib
from typing import Any, Callable, ClassVar, Protocol, Sequence

from ..errors import InputError

__all__ = ["Config", "Method", "Runner", "SearchOutcome", "NOT_SEARCHED"]

#: why a model left out of a search (``among``) has no registration, as printed
NOT_SEARCHED = "not among the models searched"


@dataclasses.dataclass(frozen=True)
class Config:
    """Base of every method's options: frozen, checked when made."""

    @classmethod
    def from_options(cls, method: str, options: dict[str, Any]) -> "Config":
        """The config with ``options`` set; an unknown name or a bad value is an InputError."""
        names = [f.name for f in dataclasses.fields(cls)]
        for key in options:
            if key not in names:
                near = difflib.get_close_matches(key, names, n=1)
                hint = f" (did you mean {near[0]!r}?)" if near else f"; its options: {', '.join(names)}"
                raise InputError(f"method {method!r} has no option {key!r}{hint}", "--method")
        try:
            return cls(**options)
        except (TypeError, ValueError) as exc:
            raise InputError(f"method {method!r}: {exc}", "--method") from None

    def _check(self, name: str, ok: bool, what: str) -> None:
        if not ok:
            raise ValueError(f"{name} must be {what}, got {getattr(self, name)!r}")


@dataclasses.dataclass(frozen=True)
class SearchOutcome:
    """What a method's search returns.

    Attributes
    ----------
    ranking : list of Registration
        One per model, in the models' order (recognition sorts them).
    settled : bool
        True when the search stopped by its rule (the best fits within the data's noise, or
        nothing is left to explore); False when its budget ran out first.
    work : int
        Closest-point queries (or the method's own unit of work) spent.
    depth : int
        How many steps of its schedule the search ran (1 for a method without one).
    allowed : int or None
        The most work the search's schedule could spend (its budget; None for a method without
        one).  ``fast``'s grids about a stall on noise-free data spend up to as much again.
    """

    ranking: list
    settled: bool = True
    work: int = 0
    depth: int = 1
    allowed: int | None = None


class Runner(Protocol):
    """Runs a stage over models, in worker processes or in this one."""

    def map(self, stage: Callable[..., list], indices: Sequence[int], *args, items: Sequence | None = None) -> list:
        """``stage(held, indices, *args[, items])`` on the models at ``indices``: one result per model, in
        the order of ``indices``.  ``items``, one per model, is split with the indices."""


class Method(Protocol):
    """A recognition method (see the module text)."""

    name: ClassVar[str]
    Config: ClassVar[type]
    #: whether :meth:`search` scores its poses on a touch's context (other touches of the object) too
    scores_context: ClassVar[bool]
    #: whether :meth:`search` runs the compiled kernels of :mod:`tactrec.engine` (loaded ahead by a
    #: one-off command: :func:`tactrec.engine.preload`)
    uses_engine: ClassVar[bool]
    #: whether its search ranks places by the catalogue's index of places (:mod:`tactrec.index`),
    #: which the recognizer then builds once
    uses_index: ClassVar[bool]

    def configure(self, **options) -> Config: ...

    def prepare(self, model) -> None: ...

    def search(self, touch, models: Sequence, config: Config, runner: Runner, *,
               among: Sequence[int] | None = None, budget: int | None = None, index=None) -> SearchOutcome:
        """One registration per model of ``models``; only those at the indices ``among`` are searched
        (all when None), the others are rejected as not searched.  ``budget``: at most this much work
        in all, when lower than the method's own budget (a method without a budget ignores it).
        ``index``: the models' :class:`~tactrec.index.PlaceIndex`, for a method that :attr:`uses_index`."""
        ...

    def refit(self, touch, models: Sequence, config: Config, runner: Runner,
              outcome: SearchOutcome) -> SearchOutcome:
        """``outcome``, the search of a touch of nearly the same points, on ``touch``: one registration per
        model, in the models' order, each error measured on ``touch``'s points; the work of both."""
        ...
