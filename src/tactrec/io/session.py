"""Session files: several touches of one still object, in one world frame (docs/formats.md).

A session is JSON with ``touches``, each a tactile data object (``curves``,
optional ``contact``, ``outward``, ``units``) in its sensor's frame, with an
optional ``sensor2world`` pose (``world = R @ sensor + t``; without it the
points are already in the world frame).  ``units`` may sit on the session.
A plain tactile data file is a session of one touch.  A touch whose approach
line met nothing has no curves and ``"missed": {"start", "direction",
"length"}`` (sensor frame; :class:`SessionMiss`).  Everything is
validated here and a problem is one :class:`~tactrec.errors.InputError`
naming the file, and the touch, and what is wrong.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import InputError
from ..linalg import norm3, rotate, times
from .atomic import write_text_atomic
from .meeting import check_meeting
from .touch import TactileData, _check_reach, _read_text, _vector, load_touch, number, parse_touch
from .values import rigid_pose

__all__ = ["SessionTouch", "SessionMiss", "MissedLine", "load_session", "parse_session_touch", "save_session",
           "is_session_file", "rigid_pose"]


@dataclasses.dataclass(frozen=True)
class SessionTouch:
    """One touch of a session: the data in its sensor's frame and the sensor's pose in the world.

    Attributes
    ----------
    data : TactileData
        Sensor frame.
    rotation, translation : (3, 3), (3,) float
        ``sensor2world``: ``world = rotation @ sensor + translation`` (identity when absent).
    """

    data: TactileData
    rotation: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))

    def in_world(self) -> TactileData:
        """The touch in the world frame."""
        return self.data.transformed(self.rotation, self.translation)

    def to_json(self) -> dict:
        out = self.data.to_json()
        out["sensor2world"] = {"rotation": self.rotation.tolist(), "translation": self.translation.tolist()}
        return out


@dataclasses.dataclass(frozen=True)
class MissedLine:
    """A line the sensor followed from ``start`` along ``direction`` (unit) for ``length`` without
    meeting anything (docs/formats.md, Where to touch next)."""

    start: np.ndarray
    direction: np.ndarray
    length: float

    @classmethod
    def parse(cls, obj, source: str) -> "MissedLine":
        """From ``{"start": [x, y, z], "direction": [x, y, z], "length": L}``, validated."""
        if not isinstance(obj, dict) or set(obj) != {"start", "direction", "length"}:
            raise InputError("'missed' must be an object with 'start', 'direction' and 'length'", source)
        start = _vector(obj["start"], "missed start", source)
        direction = _vector(obj["direction"], "missed direction", source)
        norm = float(norm3(direction))
        if norm <= 1e-12:
            raise InputError("'missed' direction has no length", source)
        length = number(obj["length"], "missed length", source)
        if length <= 0:
            raise InputError(f"'missed' length must be a positive number (got {length:g})", source)
        return cls(start, direction / norm, length)

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> "MissedLine":
        """The line under ``x -> rotation @ x + translation``."""
        return MissedLine(rotate(rotation, self.start) + translation, rotate(rotation, self.direction), self.length)

    def points(self, step: float) -> np.ndarray:
        """Points along the line ``(n, 3)``, at most ``step`` apart (both ends included; at most
        20,001)."""
        n = int(min(max(np.ceil(self.length / step), 1), 20_000)) + 1
        return self.start + np.linspace(0.0, self.length, n)[:, None] * self.direction

    def to_json(self) -> dict:
        return {"start": self.start.tolist(), "direction": self.direction.tolist(), "length": self.length}


@dataclasses.dataclass(frozen=True)
class SessionMiss:
    """A touch of a session that met nothing: its line in the sensor's frame, the sensor's pose in
    the world (as :class:`SessionTouch`) and the units."""

    line: MissedLine
    rotation: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    units: str | None = None

    def to_json(self) -> dict:
        out = {"curves": [], "missed": self.line.to_json(),
               "sensor2world": {"rotation": self.rotation.tolist(), "translation": self.translation.tolist()}}
        if self.units is not None:
            out["units"] = self.units
        return out


def is_session_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a JSON object with ``touches`` (read only as far as needed to say)."""
    path = Path(path)
    if path.suffix.lower() != ".json":
        return False
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return False
    return isinstance(obj, dict) and "touches" in obj


def load_session(path: str | os.PathLike) -> list:
    """The touches of a session file (or of a plain tactile data file: one touch, world frame):
    :class:`SessionTouch` each, or :class:`SessionMiss` for a line that met nothing.  At least one
    touch must have met the object."""
    path = Path(path)
    if not is_session_file(path):
        return [SessionTouch(load_touch(path))]
    obj = json.loads(_read_text(path))           # NaN is each touch's own error (parse_session_touch)
    touches = obj["touches"]
    if not isinstance(touches, list) or not touches:
        raise InputError("'touches' must be a non-empty list of touches", path)
    units = obj.get("units")
    out = [parse_session_touch(item, f"{path} (touch {i})", units) for i, item in enumerate(touches, start=1)]
    if not any(isinstance(t, SessionTouch) for t in out):
        raise InputError("no touch of the session met the object (every one 'missed')", path)
    # a missed line without units is in the touches' units
    kinds = {t.data.units for t in out if isinstance(t, SessionTouch)}
    kinds |= {t.units for t in out if isinstance(t, SessionMiss) and t.units is not None}
    if len(kinds) > 1:
        raise InputError(f"the touches are in different units ({', '.join(sorted(map(str, kinds)))})", path)
    return out


def parse_session_touch(item, source: str, units: str | None = None):
    """One touch of a session (docs/formats.md) from its JSON object ``item``, already parsed: a
    :class:`SessionTouch`, or a :class:`SessionMiss` for a line that met nothing; ``units`` the
    session's, for a touch that gives none; ``source`` names it in errors."""
    if not isinstance(item, dict):
        raise InputError("a touch must be a JSON object with 'curves'", source)
    pose = item.get("sensor2world")
    item = {k: v for k, v in item.items() if k != "sensor2world"}
    if units is not None and "units" not in item:
        item["units"] = units
    if pose is None:
        R, t = np.eye(3), np.zeros(3)
    elif not isinstance(pose, dict) or set(pose) != {"rotation", "translation"}:
        raise InputError("'sensor2world' must be an object with 'rotation' and 'translation'", source)
    else:
        R, t = rigid_pose(pose["rotation"], pose["translation"], source)
    if "missed" in item:
        if item.get("curves"):
            raise InputError("a touch that 'missed' has no curves", source)
        unknown = set(item) - {"missed", "curves", "units"}
        if unknown:
            raise InputError(f"a touch that 'missed' has only 'missed' and 'units' (not {sorted(unknown)[0]!r})",
                             source)
        return SessionMiss(MissedLine.parse(item["missed"], source), R, t, item.get("units"))
    data = parse_touch(item, source)
    _check_reach([times(c, R.T) + t for c in data.curves], source)    # in the world frame too
    check_meeting(data)
    return SessionTouch(data, R, t)


def save_session(touches: Sequence, path: str | os.PathLike) -> None:
    """Write a session file atomically (:class:`SessionTouch` and :class:`SessionMiss` items)."""
    units = {t.data.units if isinstance(t, SessionTouch) else t.units for t in touches}
    obj: dict = {}
    if len(units) == 1 and None not in units:
        obj["units"] = units.pop()
    obj["touches"] = []
    for t in touches:
        item = t.to_json()
        if "units" in obj:
            item.pop("units", None)
        obj["touches"].append(item)
    write_text_atomic(Path(path), json.dumps(obj) + "\n")
