"""A touch as a patch: a dense sample of the touched surface, as a vision-based skin records it.

A patch is read in one of two forms (docs/formats.md, "A patch"):

* ``points`` (optional ``normals``): surface points in the touch's frame;
* ``height``: a depth map over the sensor's plane, ``pitch`` apart, ``null`` where the sensor saw
  nothing, with the ``sensor`` pose mapping the map's frame (origin at the map's centre, x along
  columns, y along rows, depth along -z) into the touch's.

Either becomes a :class:`Patch`: its valid points, its plane's frame and the side the object is
on where the data say it (a map's sensor is outside the object; given normals point out).  The
search reads a patch as curves, like every touch (:func:`spokes`): ``SPOKES`` diameters through
the patch's middle, each sampled along the patch's surface at the patch's own spacing, so that
every stage that scores curves scores a patch unchanged, on points the sensor recorded; its local
geometry is fitted to all its points (:mod:`tactrec.estimation_patch`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError
from ..linalg import dot3, eigh, gram, times
from .values import _check_reach, _points, number, rigid_pose

__all__ = ["Patch", "parse_patch", "spokes", "SPOKES", "MAX_HOLES", "MIN_PATCH_POINTS", "SPOKE_POINTS"]

#: diameters a patch is read along (evenly turned: 180 / SPOKES degrees apart)
SPOKES = 4
#: the most of a height map's pixels that may be null
MAX_HOLES = 0.5
#: the fewest points a patch holds (a cubic fit of its surface takes 10)
MIN_PATCH_POINTS = 20
#: the most samples a spoke takes each side of the middle (a finer patch is read at a coarser step)
SPOKE_POINTS = 40


@dataclasses.dataclass(frozen=True)
class Patch:
    """A dense sample of the touched surface, in the touch's frame.

    Attributes
    ----------
    points : (n, 3) float
        The valid points.
    normals : (n, 3) float or None
        Their outward unit normals, where given.
    frame : (3, 3) float
        Rows: the patch plane's axes ``e1``, ``e2`` and its normal ``n`` (a map's: the sensor's
        x, y, z, with ``n`` pointing away from the object).
    origin : (3,) float
        A point of the plane (a map's centre).
    oriented : bool
        Whether ``n`` is known to point out of the object (a map's sensor; given normals).
    height, pitch : (rows, cols) float with NaN holes, and float; or None
        The map as read, where the patch came as one.
    point_sd : float or None
        The sensor's stated noise (a point's standard deviation, a map's along its depth; data units),
        where given: the fit test reads it in place of the patch's own estimate.
    """

    points: np.ndarray
    normals: np.ndarray | None
    frame: np.ndarray
    origin: np.ndarray
    oriented: bool
    height: np.ndarray | None = None
    pitch: float | None = None
    point_sd: float | None = None

    @property
    def spacing(self) -> float:
        """The median distance from a point to its nearest neighbour."""
        if self.pitch is not None:
            return float(self.pitch)
        d, _ = cKDTree(self.points).query(self.points, k=2)
        return float(np.median(d[:, 1]))

    def plane_coordinates(self, points: np.ndarray | None = None) -> np.ndarray:
        """``(m, 3)``: each point's ``(u, v, h)`` in the plane's frame."""
        x = self.points if points is None else points
        return times(np.asarray(x, dtype=np.float64) - self.origin, self.frame.T)

    def transformed(self, R: np.ndarray, t: np.ndarray, scale: float) -> "Patch":
        """The patch in another frame: ``x -> scale * (R x + t)``."""
        return dataclasses.replace(
            self, points=scale * (times(self.points, R.T) + t),
            normals=None if self.normals is None else times(self.normals, R.T),
            frame=times(self.frame, R.T), origin=scale * (times(self.origin, R.T) + t),
            height=None if self.height is None else scale * self.height,
            pitch=None if self.pitch is None else scale * self.pitch,
            point_sd=None if self.point_sd is None else scale * self.point_sd)

    def to_json(self) -> dict:
        if self.height is not None:
            rows = [[None if not np.isfinite(d) else float(d) for d in row] for row in self.height]
            out = {"height": rows, "pitch": self.pitch,
                   "sensor": {"rotation": self.frame.T.tolist(), "translation": self.origin.tolist()}}
        else:
            out = {"points": self.points.tolist()}
            if self.normals is not None:
                out["normals"] = self.normals.tolist()
        if self.point_sd is not None:
            out["point_sd"] = self.point_sd
        return out


def _plane(points: np.ndarray, normals: np.ndarray | None) -> tuple[np.ndarray, bool]:
    """The points' plane (rows ``e1``, ``e2``, ``n``: their scatter's axes, largest first), ``n``
    turned along the mean of ``normals`` where given."""
    centred = points - points.mean(axis=0)
    _, v = eigh(gram(centred[None])[0])
    e1, n = v[:, 2], v[:, 0]
    oriented = normals is not None
    if oriented and float(dot3(np.sum(normals, axis=0), n)) < 0:
        n = -n
    return np.stack([e1, np.cross(n, e1), n]), oriented


def _map_points(height: np.ndarray, pitch: float) -> np.ndarray:
    """A map's pixels as points of its own frame ``(rows * cols, 3)`` (NaN where null)."""
    rows, cols = height.shape
    y, x = np.meshgrid((np.arange(rows) - (rows - 1) / 2) * pitch, (np.arange(cols) - (cols - 1) / 2) * pitch,
                       indexing="ij")
    return np.stack([x, y, -height], axis=-1).reshape(-1, 3)


def parse_patch(obj, source: str) -> Patch:
    """A :class:`Patch` from a touch file's ``patch`` object; an :class:`InputError` naming ``source``
    for anything a patch cannot be."""
    if not isinstance(obj, dict) or ("points" in obj) == ("height" in obj):
        raise InputError("'patch' must be an object with either 'points' or 'height'", source)
    point_sd = None
    if obj.get("point_sd") is not None:
        point_sd = number(obj["point_sd"], "patch point_sd", source)
        if point_sd < 0:
            raise InputError(f"'patch' point_sd must not be negative (got {point_sd:g})", source)
    if "points" in obj:
        unknown = set(obj) - {"points", "normals", "point_sd"}
        if unknown:
            raise InputError(f"'patch' with 'points' takes only 'normals' and 'point_sd' besides (got "
                             f"{sorted(unknown)[0]!r})", source)
        points = _points(obj["points"], "patch point", source)
        normals = None
        if obj.get("normals") is not None:
            normals = _points(obj["normals"], "patch normal", source)
            if normals.shape != points.shape:
                raise InputError(f"'patch' has {len(points)} points but {len(normals)} normals", source)
            length = np.linalg.norm(normals, axis=1)
            if np.any(length == 0):
                raise InputError(f"patch normal {int(np.argmin(length)) + 1} is zero", source)
            normals = normals / length[:, None]
        _check_reach([points], source)
        frame, oriented = _plane(points, normals)
        patch = Patch(points, normals, frame, points.mean(axis=0), oriented, point_sd=point_sd)
    else:
        unknown = set(obj) - {"height", "pitch", "sensor", "point_sd"}
        if unknown:
            raise InputError(f"'patch' with 'height' takes 'pitch', 'sensor' and 'point_sd' besides (got "
                             f"{sorted(unknown)[0]!r})", source)
        height = _height(obj["height"], source)
        pitch = number(obj.get("pitch"), "patch pitch", source)
        if pitch <= 0:
            raise InputError(f"'patch' pitch must be positive (got {pitch:g})", source)
        R, t = _sensor(obj.get("sensor"), source)
        valid = np.isfinite(height).ravel()
        holes = 1.0 - valid.mean()
        if holes > MAX_HOLES:
            raise InputError(f"the height map is {100 * holes:.0f}% null (at most {100 * MAX_HOLES:.0f}% may be)",
                             source)
        points = times(_map_points(height, pitch)[valid], R.T) + t
        _check_reach([points], source)
        patch = Patch(points, None, R.T.copy(), t, True, height, pitch, point_sd)
    if len(patch.points) < MIN_PATCH_POINTS:
        raise InputError(f"the patch has {len(patch.points)} points; at least {MIN_PATCH_POINTS} are needed to "
                         "estimate its curvature", source)
    return patch


def _height(obj, source: str) -> np.ndarray:
    if not isinstance(obj, list) or not obj or not all(isinstance(row, list) for row in obj):
        raise InputError("'patch' height must be a list of rows of depths", source)
    if len({len(row) for row in obj}) != 1:
        raise InputError("'patch' height rows differ in length", source)
    try:
        arr = np.array([[np.nan if d is None else d for d in row] for row in obj], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError("'patch' height must hold numbers or null", source) from None
    if arr.shape[0] < 2 or arr.shape[1] < 2:
        raise InputError(f"'patch' height is {arr.shape[0]} x {arr.shape[1]}: a map needs rows and columns", source)
    if np.isinf(arr).any():
        raise InputError("'patch' height holds an infinite depth", source)
    return arr


def _sensor(obj, source: str) -> tuple[np.ndarray, np.ndarray]:
    """The map-to-touch pose ``R, t`` (identity where not given), a rigid motion (:func:`.values.rigid_pose`)."""
    if obj is None:
        return np.eye(3), np.zeros(3)
    if not isinstance(obj, dict) or set(obj) != {"rotation", "translation"}:
        raise InputError("'patch' sensor must be an object with 'rotation' and 'translation'", source)
    return rigid_pose(obj["rotation"], obj["translation"], source, "patch sensor")


def spokes(patch: Patch, source: str) -> tuple[list[np.ndarray], np.ndarray]:
    """The curves a patch is searched along, and their common point ``(3,)``: points the sensor
    recorded, none made up.

    :data:`SPOKES` diameters through the patch's middle (its point nearest the mean of the points'
    plane coordinates), evenly turned from the plane's ``e1``; along each, every ``step`` (the
    patch's spacing over the larger of the direction's two components, so that on a map's rows,
    columns and diagonals each step is one pixel, and coarser where that would give more than
    :data:`SPOKE_POINTS` a side) the patch's point nearest the diameter's sample, to where the patch
    ends or a hole begins (no point within half a spacing).  An :class:`InputError` where a spoke
    has fewer than 5 points: the patch is too small, or too holed, to estimate its curvature."""
    uvh = patch.plane_coordinates()
    tree = cKDTree(uvh[:, :2])
    middle = uvh[int(tree.query(uvh[:, :2].mean(axis=0))[1]), :2]
    spacing = patch.spacing
    reach = float(np.max(np.linalg.norm(uvh[:, :2] - middle, axis=1)))
    coarse = max(1, int(np.ceil(reach / (SPOKE_POINTS * spacing))))
    curves, contact = [], None
    for i in range(SPOKES):
        angle = np.pi * i / SPOKES
        direction = np.array([np.cos(angle), np.sin(angle)])
        step = coarse * spacing / np.max(np.abs(direction))
        k = int(np.floor(reach / step))
        samples = middle + np.arange(-k, k + 1)[:, None] * step * direction
        gap, nearest = tree.query(samples)
        ok = gap <= 0.5 * spacing
        lo = hi = k                                                # the run of points around the middle
        while lo > 0 and ok[lo - 1]:
            lo -= 1
        while hi < 2 * k and ok[hi + 1]:
            hi += 1
        if hi - lo + 1 < 5:
            raise InputError(f"the patch is too small, or too holed, to estimate curvature: {hi - lo + 1} points "
                             f"along one line through its middle (at least 5, {step:.3g} apart)", source)
        run = nearest[lo:hi + 1]
        if len(np.unique(run)) < len(run):
            raise InputError("the patch's points are too uneven to read along lines through its middle", source)
        curves.append(patch.points[run])
        contact = patch.points[nearest[k]] if contact is None else contact
    return curves, contact
