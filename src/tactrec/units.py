"""Length units of data files and models."""

from __future__ import annotations

__all__ = ["UNITS", "unit_scale", "conversion"]

#: metres per unit
UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "in": 0.0254}


def unit_scale(units: str) -> float:
    """Metres per ``units``; ``ValueError`` for a unit that is not known."""
    if not isinstance(units, str) or units not in UNITS:
        raise ValueError(f"unknown units {units!r}; expected one of {', '.join(UNITS)}")
    return UNITS[units]


def conversion(source: str | None, target: str | None) -> float:
    """Factor taking lengths in ``source`` units to ``target`` units.

    Where either side does not say its units, lengths are taken as they are.
    """
    if source is None or target is None:
        return 1.0
    return unit_scale(source) / unit_scale(target)
