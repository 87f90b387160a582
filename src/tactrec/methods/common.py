"""Helpers the methods share: units and the two orientations of an unoriented normal."""

from __future__ import annotations

import dataclasses
from typing import Callable

from ..features import Touch
from ..registration.result import Registration
from ..units import conversion

__all__ = ["in_model_units", "best_of_orientations"]


def in_model_units(touch: Touch, model) -> Touch:
    """``touch`` in ``model``'s units (the same object when they agree)."""
    return touch.in_units(conversion(touch.data.units, getattr(model, "units", None)))


def best_of_orientations(register: Callable[..., Registration], touch: Touch, name: str) -> Registration:
    """``register(geometry, sign)`` for each normal of ``touch`` to try (:attr:`~tactrec.features.Touch.sides`);
    the better registration, marked with the sign of the normal it used and the touch's unit scale (a
    rejection if none is ok)."""
    results = [dataclasses.replace(register(g, sign), normal_sign=sign, scale=touch.scale)
               for sign, g in touch.sides]
    ok = [r for r in results if r.ok]
    if not ok:
        return Registration.unfitted(name, results[0].reason, results[0].outcome, scale=touch.scale)
    best = min(ok, key=lambda r: r.error)
    return dataclasses.replace(best, candidates=sum(r.candidates for r in results))
