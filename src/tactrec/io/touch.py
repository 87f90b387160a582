"""Tactile data: three or more planar curves meeting at one point (Section 3.1), a patch, or contacts.

Files (docs/formats.md): JSON with ``curves``, optional ``contact``, ``outward``,
``units``; or CSV with the header ``curve,x,y,z``; or JSON with a ``patch``
(:mod:`.patch`: the search reads it along curves through its middle, its spokes); or JSON with
``contacts`` (:mod:`.contacts`: each a curve of one point to every stage that scores a pose).  Everything is validated
here, at the boundary, and a problem is reported as one
:class:`~tactrec.errors.InputError` naming the file and what is wrong.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..errors import InputError
from ..linalg import norm3, times
from ..units import unit_scale
from .atomic import write_text_atomic
from .meeting import check_meeting
from .contacts import Contacts, parse_contacts
from .patch import Patch, parse_patch, spokes
from .values import FAR, MAX_COORDINATE, _check_reach, _points, _vector, number  # noqa: F401  (read here too)

__all__ = ["TactileData", "load_touch", "save_touch", "parse_touch", "read_json", "MIN_CURVES", "MIN_POINTS"]

MIN_CURVES = 3
MIN_POINTS = 5


@dataclasses.dataclass(frozen=True)
class TactileData:
    """Points along three or more concurrent planar curves, in the sensor's frame.

    Attributes
    ----------
    curves : tuple of (n_i, 3) float arrays
        Ordered points along each curve.
    contact : (3,) float or None
        The common point ``p`` of the curves, if known.
    outward : (3,) float or None
        A direction pointing away from the object at ``p``, if known.
    units : str or None
        Length units of the coordinates (``"mm"``, ``"m"``, ...).
    tip_radius : float
        The points are the centres of a spherical tip of this radius (data units; 0: points on
        the surface).
    patch : Patch or None
        Where the touch is a patch (:mod:`.patch`): its points; ``curves`` are then its spokes
        and ``contact`` their common point.
    contacts : Contacts or None
        Where the touch is single contacts (:mod:`.contacts`): ``curves`` are then its points, one
        a curve, and ``contact`` is None.
    meta : dict
        Anything else the file carried (e.g. ``"truth"`` of a simulated touch).
    source : str
        Where the data came from (file name), for messages.
    """

    curves: tuple[np.ndarray, ...]
    contact: np.ndarray | None = None
    outward: np.ndarray | None = None
    units: str | None = None
    meta: dict = dataclasses.field(default_factory=dict)
    source: str = "<data>"
    tip_radius: float = 0.0
    patch: Patch | None = None
    contacts: Contacts | None = None

    @property
    def kind(self) -> str:
        """``"curves"``, ``"patch"`` or ``"contacts"``."""
        return "patch" if self.patch is not None else "contacts" if self.contacts is not None else "curves"

    @classmethod
    def from_contacts(cls, contacts: Contacts, *, units=None, meta=None, source: str = "<data>") -> "TactileData":
        """A touch of single contacts: each point a curve of one point (what every stage that scores a
        pose reads); no contact point, no outward hint (each contact gives its own normal)."""
        if units is not None:
            try:
                unit_scale(units)
            except ValueError as exc:
                raise InputError(str(exc), source) from None
        return cls(tuple(p[None].copy() for p in contacts.points), None, None, units, dict(meta or {}), source,
                   contacts=contacts)

    @classmethod
    def from_patch(cls, patch: Patch, *, outward=None, units=None, meta=None, source: str = "<data>",
                   tip_radius=0.0) -> "TactileData":
        """A patch's touch: its spokes (:func:`.patch.spokes`) as the curves, their common point as the
        contact, the outward direction given or the patch's own where it knows it."""
        curves, contact = spokes(patch, source)
        if outward is None and patch.oriented:
            outward = patch.frame[2]
        data = cls.from_arrays(curves, contact=contact, outward=outward, units=units, meta=meta, source=source,
                               tip_radius=tip_radius)
        return dataclasses.replace(data, patch=patch)

    @classmethod
    def from_arrays(cls, curves: Sequence, *, contact=None, outward=None, units=None,
                    meta=None, source: str = "<data>", tip_radius=0.0) -> "TactileData":
        """Validate and build.  Raises :class:`InputError` naming ``source``."""
        if not isinstance(curves, (list, tuple)) and not (isinstance(curves, np.ndarray) and curves.ndim == 3):
            raise InputError("'curves' must be a list of curves", source)
        if len(curves) < MIN_CURVES:
            raise InputError(f"needs at least {MIN_CURVES} curves, got {len(curves)} (the normal curvatures of fewer "
                             "directions leave the principal curvatures undetermined)", source)
        arrays = [_points(c, f"curve {i + 1}", source) for i, c in enumerate(curves)]
        for i, arr in enumerate(arrays):
            if len(arr) < MIN_POINTS:
                raise InputError(f"curve {i + 1} has {len(arr)} points; at least {MIN_POINTS} are needed", source)
        _check_reach(arrays, source)
        for i, arr in enumerate(arrays):
            if np.ptp(arr, axis=0).max() == 0:
                raise InputError(f"curve {i + 1} has all its points at one place", source)
        c = None if contact is None else _vector(contact, "contact", source)
        o = None if outward is None else _vector(outward, "outward", source)
        if o is not None:
            norm = norm3(o)
            if norm == 0:
                raise InputError("'outward' must be a non-zero direction", source)
            o = o / norm
        if units is not None:
            try:
                unit_scale(units)
            except ValueError as exc:
                raise InputError(str(exc), source) from None
        tip = number(tip_radius, "tip_radius", source)
        if tip < 0:
            raise InputError(f"'tip_radius' must be a non-negative number (got {tip_radius!r})", source)
        return cls(tuple(arrays), c, o, units, dict(meta or {}), source, tip)

    @property
    def points(self) -> np.ndarray:
        """All points, ``(n, 3)``."""
        return np.concatenate(self.curves)

    @property
    def spacing(self) -> float:
        """Median distance between neighbouring points of a curve (of contacts: from each to its nearest)."""
        if self.contacts is not None:
            x = self.contacts.points
            d = np.linalg.norm(x[:, None] - x[None], axis=2) + np.diag(np.full(len(x), np.inf))
            return float(np.median(d.min(axis=1))) if len(x) > 1 else 0.0
        return float(np.median(np.concatenate([np.linalg.norm(np.diff(c, axis=0), axis=1) for c in self.curves])))

    def transformed(self, rotation: np.ndarray, translation: np.ndarray, *, scale: float = 1.0) -> "TactileData":
        """The same touch in another frame: ``x -> scale * (R x + t)``."""
        R = np.asarray(rotation, dtype=np.float64)
        t = np.asarray(translation, dtype=np.float64)
        move = lambda p: scale * (times(p, R.T) + t)  # noqa: E731
        return dataclasses.replace(
            self,
            curves=tuple(move(c) for c in self.curves),
            contact=None if self.contact is None else move(self.contact),
            outward=None if self.outward is None else times(self.outward, R.T),
            tip_radius=scale * self.tip_radius,
            patch=None if self.patch is None else self.patch.transformed(R, t, scale),
            contacts=None if self.contacts is None else self.contacts.transformed(R, t, scale),
        )

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.units is not None:
            out["units"] = self.units
        if self.contacts is not None:
            out["contacts"] = self.contacts.to_json()
        elif self.patch is not None:
            out["patch"] = self.patch.to_json()
            if not self.patch.oriented and self.outward is not None:
                out["outward"] = self.outward.tolist()
        else:
            out["curves"] = [c.tolist() for c in self.curves]
        if self.contact is not None and self.patch is None:
            out["contact"] = self.contact.tolist()
        if self.outward is not None and self.patch is None and self.contacts is None:
            out["outward"] = self.outward.tolist()
        if self.tip_radius > 0:
            out["tip_radius"] = self.tip_radius
        out.update(self.meta)
        return out


def _read_text(path: Path) -> str:
    try:
        text = path.read_text(encoding="utf-8-sig")             # a byte-order mark (spreadsheet exports) is read past
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except IsADirectoryError:
        raise InputError("is a directory, not a data file", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read file ({exc.__class__.__name__})", path) from None
    if not text.strip():
        raise InputError("empty file", path)
    return text


def read_json(text: str, source: str):
    """The JSON value of ``text``; ``NaN`` and ``Infinity``, which JSON does not have, and numbers too
    large for a float (``1e999``) are one line."""
    def no_constant(name):
        raise InputError(f"not valid JSON: {name} is not a number", source)

    def finite(text):
        value = float(text)
        if not math.isfinite(value):
            raise InputError(f"the number {text[:20]} is too large", source)
        return value

    try:
        return json.loads(text, parse_constant=no_constant, parse_float=finite)
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})", source) from None
    except RecursionError:
        raise InputError("not valid JSON: nested too deeply", source) from None


def _parse_json(text: str, source: str) -> TactileData:
    obj = read_json(text, source)
    return parse_touch(obj, source)


def parse_touch(obj, source: str) -> TactileData:
    """A touch from the JSON object ``obj`` of a tactile data file (docs/formats.md), already parsed
    (a service's request, :mod:`tactrec.service`); ``source`` names it in errors."""
    if not isinstance(obj, dict):
        raise InputError("expected a JSON object with 'curves'", source)
    kinds = [k for k in KINDS if k in obj]
    if len(kinds) != 1:
        raise InputError("missing 'curves'" if not kinds else
                         f"a touch carries one of {', '.join(KINDS)} (got {' and '.join(kinds)})", source)
    meta = {k: v for k, v in obj.items() if k not in {*KINDS, "contact", "outward", "units", "tip_radius"}}
    if kinds[0] == "contacts":
        for key in ("contact", "outward", "tip_radius"):
            if key in obj:
                raise InputError(f"a touch of contacts takes no {key!r}: each contact gives its own point and "
                                 "normal", source)
        return TactileData.from_contacts(parse_contacts(obj["contacts"], source), units=obj.get("units"),
                                         meta=meta, source=source)
    if kinds[0] == "patch":
        if "contact" in obj:
            raise InputError("a patch takes no 'contact': its middle is where it is read", source)
        return TactileData.from_patch(parse_patch(obj["patch"], source), outward=obj.get("outward"),
                                      units=obj.get("units"), meta=meta, source=source,
                                      tip_radius=obj.get("tip_radius", 0.0))
    return TactileData.from_arrays(obj["curves"], contact=obj.get("contact"), outward=obj.get("outward"),
                                   units=obj.get("units"), meta=meta, source=source,
                                   tip_radius=obj.get("tip_radius", 0.0))


#: what a touch may carry: one of these
KINDS = ("curves", "patch", "contacts")

#: the columns a CSV touch may have: the coordinates, the curve's (or stroke's) label, the time
_CSV_COLUMNS = ("curve", "stroke", "t", "x", "y", "z")


def _csv_header(header: list, source: str) -> dict:
    """Column index by name (docs/formats.md, A touch): ``x``, ``y``, ``z``, at most one of ``curve``
    and ``stroke`` and an optional ``t``, in any order."""
    unknown = [h for h in header if h not in _CSV_COLUMNS]
    if unknown or len(set(header)) != len(header) or not {"x", "y", "z"} <= set(header) \
            or {"curve", "stroke"} <= set(header):
        raise InputError(f"CSV header must name x, y and z, with 'curve' (or 'stroke') and an optional 't' "
                         f"(got {','.join(header)!r})", source)
    return {name: header.index(name) for name in header}


def _csv_number(cell: str, what: str, line_no: int, source: str) -> float:
    try:
        value = float(cell)
    except ValueError:
        raise InputError(f"line {line_no}: {what} must be a number (got {cell!r})", source) from None
    if not math.isfinite(value):
        raise InputError(f"line {line_no}: {what} is not finite ({cell.strip()})", source)
    return value


def _parse_csv(text: str, source: str) -> TactileData:
    """A CSV touch (docs/formats.md): a label column names each point's curve, or, without one, the
    rows are a sensor's stream and a row with no coordinates (the sensor lifted) ends a stroke; a
    ``t`` column orders each curve's points and the curves."""
    reader = csv.reader(io.StringIO(text))
    try:
        header = [h.strip().lower() for h in next(reader)]
    except (StopIteration, csv.Error):
        raise InputError("empty CSV", source) from None
    col = _csv_header(header, source)
    label = col.get("curve", col.get("stroke"))
    curves: dict[str, list] = {}
    extra: dict[str, list] = {}
    stroke = 0
    try:
        for line_no, row in enumerate(reader, start=2):
            blank = not row or all(not cell.strip() for cell in row)
            if blank and label is not None:
                continue
            if not blank and len(row) != len(header):
                raise InputError(f"line {line_no}: expected {len(header)} fields, got {len(row)}", source)
            if blank or (label is None and all(not row[col[a]].strip() for a in "xyz")):
                stroke += 1 if curves.get(str(stroke)) else 0            # the sensor lifted: a new stroke
                continue
            point = [_csv_number(row[col[a]], "coordinates", line_no, source) for a in "xyz"]
            key = row[label].strip() if label is not None else str(stroke)
            if key in {"contact", "outward"}:
                extra.setdefault(key, []).append(point)
                continue
            t = _csv_number(row[col["t"]], "t", line_no, source) if "t" in col else 0.0
            curves.setdefault(key, []).append((t, point))
    except csv.Error as exc:
        raise InputError(f"malformed CSV ({exc})", source) from None
    for key, pts in extra.items():
        if len(pts) != 1:
            raise InputError(f"'{key}' must be given on one line", source)
    # each curve in time order, and the curves by when they start (stable sorts: rows at one time keep
    # the file's order, and without times the curves are in the order they first appear)
    runs = sorted(curves.values(), key=lambda rows: min(t for t, _ in rows))
    ordered = [[p for _, p in sorted(rows, key=lambda row: row[0])] for rows in runs]
    return TactileData.from_arrays(ordered, contact=extra.get("contact", [None])[0],
                                   outward=extra.get("outward", [None])[0], source=source)


def load_touch(path: str | os.PathLike) -> TactileData:
    """Load a touch from a ``.json`` or ``.csv`` file and validate it.

    The curves must meet at one point (checked here, see
    :func:`tactrec.io.meeting.find_contact`).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in {".json", ".csv"}:
        raise InputError(f"unsupported data format {suffix!r}; expected .json or .csv", path)
    text = _read_text(path)
    data = _parse_json(text, str(path)) if suffix == ".json" else _parse_csv(text, str(path))
    if data.kind == "curves":
        check_meeting(data)
    return data


def save_touch(data: TactileData, path: str | os.PathLike) -> None:
    """Write a touch as JSON (or CSV, by suffix), atomically."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        if data.tip_radius > 0 or data.kind != "curves":
            raise InputError(f"a CSV touch file has no place for {'tip_radius' if data.kind == 'curves' else data.kind}:"
                             " write it as .json", path)
        lines = ["curve,x,y,z"]
        for i, c in enumerate(data.curves, start=1):
            lines += [f"{i},{x!r},{y!r},{z!r}" for x, y, z in c.tolist()]
        for key in ("contact", "outward"):
            vec = getattr(data, key)
            if vec is not None:
                lines.append(f"{key},{vec[0]!r},{vec[1]!r},{vec[2]!r}")
        write_text_atomic(path, "\n".join(lines) + "\n")
    else:
        write_text_atomic(path, json.dumps(data.to_json()) + "\n")
