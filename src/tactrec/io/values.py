"""The values a touch file holds, checked at the boundary: points, vectors, numbers, and coordinates
a sensor can record.  Each problem is one :class:`~tactrec.errors.InputError` naming the file."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..linalg import compose, det3

__all__ = ["MAX_COORDINATE", "FAR", "number", "rigid_pose"]


#: no sensor records coordinates beyond this magnitude, nor a touch spanning less than its inverse, in any
#: units (a thousand km in micrometres, a picometre in metres)
MAX_COORDINATE = 1e12
#: nor a touch farther from its frame's origin than this many times its own extent
FAR = 1e6


def _check_reach(arrays: list, source: str) -> None:
    """Refuse, before any arithmetic on them, coordinates no sensor records: beyond
    :data:`MAX_COORDINATE`, a touch spanning less than its inverse, or a touch more than :data:`FAR`
    times its extent from its frame's origin (its shape would be lost in the coordinates' rounding)."""
    reach = max(float(np.max(np.abs(a))) for a in arrays)
    if reach > MAX_COORDINATE:
        raise InputError(f"coordinates reach {reach:.3g}: no sensor records beyond {MAX_COORDINATE:.0e} in any "
                         "units", source)
    points = np.concatenate(arrays)
    extent = float(np.max(points.max(axis=0) - points.min(axis=0)))
    if 0 < extent < 1.0 / MAX_COORDINATE:
        raise InputError(f"the touch spans {extent:.3g}: no sensor records under {1.0 / MAX_COORDINATE:.0e} in any "
                         "units", source)
    if extent > 0 and reach > FAR * extent:
        raise InputError(f"the touch spans {extent:.3g} but lies {reach:.3g} from its frame's origin (more than "
                         f"{FAR:.0e} times its extent): these are not a sensor's coordinates", source)


def _points(obj, what: str, source: str) -> np.ndarray:
    if not isinstance(obj, (list, tuple, np.ndarray)):
        raise InputError(f"{what} must be a list of [x, y, z] points", source)
    try:
        arr = np.array(obj, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{what} must be a list of [x, y, z] numbers", source) from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"{what} must be a list of [x, y, z] points (got shape {arr.shape})", source)
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise InputError(f"{what} point {int(np.argmax(bad)) + 1} is not finite ({arr[bad][0].tolist()})", source)
    return arr


def _vector(obj, what: str, source: str) -> np.ndarray:
    """Three finite numbers, each within :data:`MAX_COORDINATE`."""
    try:
        arr = np.array(obj, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"'{what}' must be [x, y, z] numbers", source) from None
    if arr.shape != (3,):
        raise InputError(f"'{what}' must be [x, y, z] (got {obj!r})", source)
    if not np.isfinite(arr).all():
        raise InputError(f"'{what}' is not finite ({arr.tolist()})", source)
    if np.max(np.abs(arr)) > MAX_COORDINATE:
        raise InputError(f"'{what}' reaches {np.max(np.abs(arr)):.3g}: no sensor records beyond "
                         f"{MAX_COORDINATE:.0e} in any units", source)
    return arr


def number(obj, what: str, source: str) -> float:
    """A finite number within :data:`MAX_COORDINATE` (not a bool), as a float."""
    try:
        if isinstance(obj, bool) or not isinstance(obj, (int, float, np.floating, np.integer)):
            raise TypeError
        value = float(obj)
    except (TypeError, OverflowError):
        raise InputError(f"'{what}' must be a number (got {str(obj)[:40]})", source) from None
    if not math.isfinite(value) or abs(value) > MAX_COORDINATE:
        raise InputError(f"'{what}' must be a finite number within {MAX_COORDINATE:.0e} (got {value:.3g})", source)
    return value


def rigid_pose(rotation, translation, source: str, what: str = "sensor2world") -> tuple[np.ndarray, np.ndarray]:
    """Validate a rigid motion: ``rotation`` a proper rotation (orthonormal to 1e-6, determinant +1)
    and ``translation`` three finite numbers.  Returns them as arrays."""
    try:
        R = np.array(rotation, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"'{what}' rotation must be a 3 x 3 array of numbers", source) from None
    if R.shape != (3, 3) or not np.isfinite(R).all():
        raise InputError(f"'{what}' rotation must be a 3 x 3 array of finite numbers", source)
    if np.max(np.abs(R)) > 2.0:
        raise InputError(f"'{what}' rotation is not a rotation (an entry reaches {np.max(np.abs(R)):.3g})", source)
    if np.max(np.abs(compose(R, R.T) - np.eye(3))) > 1e-6 or det3(R) < 0:
        raise InputError(f"'{what}' rotation is not a rotation (orthonormal, determinant +1)", source)
    return R, _vector(translation, f"{what} translation", source)
