"""A truncated signed distance field per mesh model, stored sparsely in bricks.

The engine (:mod:`tactrec.engine`) scores hypotheses by the distance of the
data points to the model.  An exact closest-point query (libigl's AABB tree)
costs about fifty trilinear lookups in a grid, so the breadth of the search
is scored on a grid and exact distances only refine and decide.

* **Spacing** follows the mesh: ``SPACING`` x its mean edge.
* **Truncation**: the field is kept where the surface is within ``BAND``
  cells; elsewhere a lookup returns the truncation ``BAND x spacing``.  Only
  blocks of ``BRICK`` cells a side that hold such a cell are stored (``bricks``),
  each with its corner samples (``BRICK + 1`` a side, so that no lookup
  crosses bricks), as 16-bit integers in units of ``truncation / 32767``.
* **Sign**: positive on the side of the surface's outward normal, by the
  angle-weighted pseudonormal of the closest feature (libigl's normals).  On a
  closed mesh that is outside; on an open scan it is the side of the nearest
  surface's normal, which within the band, where the field is kept, is what
  a point-to-plane step needs.  Beyond the band a sample takes the side of
  its neighbour (:mod:`.field_raster`).  Screens use the distance's magnitude.
* **Build**: each face is swept over the samples of the bricks within the
  band of it (:mod:`.field_raster`), not each sample searched for its
  nearest face.

Trilinear interpolation is exact on a plane and off by about
``spacing^2 |kappa| / 8`` on a curved patch; near an edge or a thin wall it
is coarser.  ``tactrec bench field`` measures it against exact distances.
"""

from __future__ import annotations

import dataclasses
import os
from typing import ClassVar

import numpy as np

__all__ = ["DistanceField", "FieldsElsewhere", "build_field", "SPACING", "BAND"]

#: grid spacing as a multiple of the mesh's mean edge
SPACING = 0.35
#: truncation, in cells
BAND = 4
#: largest stored magnitude
_Q = 32767


@dataclasses.dataclass(frozen=True)
class DistanceField:
    """A sparse truncated signed distance field (see the module text).

    Attributes
    ----------
    origin : (3,) float
        The grid's first corner, model frame.
    spacing : float
        Cell size, model units.
    truncation : float
        Distances are clipped to ``[-truncation, truncation]``.
    index : (bx, by, bz) int32
        Brick of each block of ``BRICK`` cells, -1 where none is stored.
    bricks : (nb, BRICK + 1, BRICK + 1, BRICK + 1) int16
        Signed distances at the cells' corners, in units of :attr:`quantum`.
    shift : float
        Subtracted from every sample: the field of the surface offset outward by ``shift``, read
        from the same bricks (:meth:`shifted`); 0 for the field as sampled.
    """

    #: the names it is stored under (:meth:`to_store`)
    KEYS: ClassVar[tuple] = ("field_origin", "field_spacing", "field_truncation", "field_index", "field_bricks")

    origin: np.ndarray
    spacing: float
    truncation: float
    index: np.ndarray
    bricks: np.ndarray
    shift: float = 0.0

    @property
    def quantum(self) -> float:
        return self.truncation / _Q

    @property
    def band(self) -> float:
        """How far from its surface the field reads true distances: the truncation less the shift."""
        return self.truncation - abs(self.shift)

    def shifted(self, by: float) -> "DistanceField":
        """The field of the surface offset outward by ``by`` (inward where negative), read from these
        bricks: every sample less ``by``, within the band the shift leaves (:attr:`band`).  The
        trilinear interpolation of ``d - by`` is that of ``d`` less ``by``, so within that band it is
        the field a build of the offset would sample on this grid.  ``ValueError`` where the shift
        leaves no band."""
        field = dataclasses.replace(self, shift=self.shift + float(by))
        if not field.band > 0:
            raise ValueError(f"a shift of {field.shift:g} leaves no band of a field truncated at {self.truncation:g}")
        return field

    @property
    def nbytes(self) -> int:
        return int(self.index.nbytes + self.bricks.nbytes)

    def args(self) -> tuple:
        """The arguments every field kernel (:mod:`.field_kernels`, :mod:`tactrec.engine.kernels`) takes first."""
        return (self.index, self.bricks, self.origin, 1.0 / self.spacing, self.quantum, self.band, self.shift)

    def signed(self, points: np.ndarray) -> np.ndarray:
        """Signed, truncated distances of ``points (..., 3)``, shape ``(...)``."""
        from .field_kernels import field_lookup

        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        return field_lookup(*self.args(), p).reshape(np.shape(points)[:-1])

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Truncated distances (magnitudes) of ``points (..., 3)``, shape ``(...)``."""
        return np.abs(self.signed(points))

    def to_store(self) -> dict[str, np.ndarray]:
        if self.shift:
            raise ValueError("a shifted field is read from its source's bricks; store the source")
        return {"field_origin": self.origin, "field_spacing": np.array(self.spacing),
                "field_truncation": np.array(self.truncation), "field_index": self.index,
                "field_bricks": self.bricks}

    @classmethod
    def from_store(cls, arrays) -> "DistanceField":
        from .field_kernels import BRICK

        origin = np.ascontiguousarray(arrays["field_origin"], dtype=np.float64)
        spacing, truncation = float(arrays["field_spacing"]), float(arrays["field_truncation"])
        index = np.ascontiguousarray(arrays["field_index"])
        bricks = arrays["field_bricks"]
        if (origin.shape != (3,) or not np.all(np.isfinite(origin)) or not spacing > 0 or not truncation > 0
                or index.ndim != 3 or index.dtype != np.int32 or bricks.dtype != np.int16
                or bricks.ndim != 4 or bricks.shape[1:] != (BRICK + 1,) * 3
                or (index.size and (index.min() < -1 or index.max() >= len(bricks)))):
            raise ValueError("the stored distance field is malformed")
        return cls(origin, spacing, truncation, index, bricks)


def _face_bricks(vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, block: float, reach: float,
                 shape: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of a block and a face whose bounding box, grown by ``reach``, meets it: the blocks'
    keys (their flat index in a grid of ``shape``) and the faces, ``(p,)`` each."""
    tri = vertices[faces]
    lo = np.clip(np.floor((tri.min(axis=1) - reach - origin) / block).astype(np.int64), 0, shape - 1)
    hi = np.clip(np.floor((tri.max(axis=1) + reach - origin) / block).astype(np.int64), 0, shape - 1)
    span = int((hi - lo).max()) + 1
    keys, found = [], []
    for dx in range(span):
        for dy in range(span):
            for dz in range(span):
                b = lo + np.array([dx, dy, dz])
                ok = np.flatnonzero(np.all(b <= hi, axis=1))
                keys.append((b[ok, 0] * shape[1] + b[ok, 1]) * shape[2] + b[ok, 2])
                found.append(ok)
    return np.concatenate(keys), np.concatenate(found)


def _listed(keys: np.ndarray, faces: np.ndarray, kept: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each block of ``kept`` (keys, increasing) the faces paired with it in ``keys, faces``
    (:func:`_face_bricks`): ``starts (k + 1,)`` and ``listed``, block ``i``'s faces
    ``listed[starts[i]:starts[i + 1]]`` in increasing order."""
    if not len(kept):
        return np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    at = np.minimum(np.searchsorted(kept, keys), len(kept) - 1)
    found = kept[at] == keys
    where, faces = at[found], faces[found]
    sort = np.lexsort((faces, where))
    starts = np.concatenate([[0], np.cumsum(np.bincount(where, minlength=len(kept)))])
    return starts.astype(np.int64), np.ascontiguousarray(faces[sort], dtype=np.int64)


def build_field(vertices: np.ndarray, faces: np.ndarray, *, mean_edge: float, spacing: float | None = None,
                band: int = BAND, offset: float = 0.0) -> DistanceField:
    """The truncated signed distance field of a mesh (see the module text): its spacing is
    ``SPACING x mean_edge`` unless given.  With ``offset`` > 0 it is the field of the surface offset
    outward by that much (the centres of a round tip of that radius, :mod:`tactrec.tip`): the
    signed distance minus ``offset``, kept within the band of that offset surface."""
    import igl

    from .field_kernels import BRICK
    from .field_raster import brick_distances

    h = float(spacing if spacing is not None else SPACING * mean_edge)
    truncation = band * h
    block = BRICK * h
    r = float(offset)
    reach = r + truncation
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    origin = low - reach - h
    shape = np.floor((high + reach + h - origin) / block).astype(np.int64) + 1
    keys, paired = _face_bricks(vertices, faces, origin, block, reach, shape)
    kept = np.unique(keys)                                  # the blocks any face's grown box meets
    blocks = np.stack([kept // (shape[1] * shape[2]), (kept // shape[2]) % shape[1], kept % shape[2]], axis=1)
    # a brick is kept where a corner lies within the band; the unsigned distance moves by at most the
    # half diagonal from the brick's centre, so a brick whose centre is farther is not sampled
    centre = origin + (blocks + 0.5) * block
    near, _, _ = igl.point_mesh_squared_distance(centre, vertices, faces)
    sampled = np.abs(np.sqrt(np.asarray(near, dtype=np.float64)) - r) <= truncation + 0.5 * np.sqrt(3.0) * block \
        + 1e-9 * block
    blocks, kept = blocks[sampled], kept[sampled]
    # each face is swept over the samples of the bricks within reach of it (:mod:`.field_raster`)
    starts, listed = _listed(keys, paired, kept)
    fn = igl.per_face_normals(vertices, faces, np.full(3, 1.0 / np.sqrt(3.0)))
    vn = igl.per_vertex_normals(vertices, faces, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_ANGLE)
    en, _, emap = igl.per_edge_normals(vertices, faces, igl.PER_EDGE_NORMALS_WEIGHTING_TYPE_UNIFORM)
    c = np.ascontiguousarray
    d = brick_distances(c(vertices, dtype=np.float64), c(faces, dtype=np.int64), c(fn), c(vn), c(en),
                        c(np.asarray(emap, dtype=np.int64).reshape(3, len(faces)).T), c(origin), h, reach,
                        c(blocks, dtype=np.int64), starts, listed, BRICK).reshape(len(blocks), -1) - r
    d = np.clip(d, -truncation, truncation)
    keep = np.min(np.abs(d), axis=1) < truncation
    blocks, d = blocks[keep], d[keep]
    index = np.full(tuple(shape), -1, dtype=np.int32)
    index[blocks[:, 0], blocks[:, 1], blocks[:, 2]] = np.arange(len(blocks), dtype=np.int32)
    bricks = np.round(d * (_Q / truncation)).astype(np.int16).reshape((len(blocks),) + (BRICK + 1,) * 3)
    return DistanceField(np.ascontiguousarray(origin), h, truncation, index, bricks)


class FieldsElsewhere:
    """In place of a mesh's stored arrays where its distance fields are read elsewhere (a cluster's
    workers; :func:`tactrec.database.load_database` without ``fields``): reading a field here
    (``field_*``, ``outer_*``, ``offset*``) is an error, never a silent rebuild.  It keeps the other
    arrays, but for those the mesh and its table already hold (``mesh_*``, ``table_*``)."""

    FIELDS = ("field_", "outer_", "offset")

    def __init__(self, arrays, source):
        self.source = source
        held = self.FIELDS + ("mesh_", "table_")
        self.kept = {k: np.asarray(arrays[k]) for k in arrays.files if not k.startswith(held)}

    def _check(self, key) -> None:
        if str(key).startswith(self.FIELDS):
            raise RuntimeError(f"{self.source}: loaded without its distance fields (the cluster's workers read "
                               f"them), yet {key} was read here")

    def __contains__(self, key) -> bool:
        self._check(key)
        return key in self.kept

    def __getitem__(self, key):
        self._check(key)
        return self.kept[key]


class FieldsOnDisk:
    """In place of a mesh's stored arrays, those of its database file read when used (a distance field
    on its model's first search, a tip's offset field on the first touch with that tip): the
    compressed file is not kept in memory, about as much again as the field it holds.  The file is
    opened anew for each read, and must be the one whose checksum was checked on loading (its size
    and modification time unchanged), else the read is an :class:`~tactrec.errors.InputError`."""

    def __init__(self, path, files):
        self.path = path
        self.files = tuple(files)
        stat = os.stat(path)
        self._stamp = (stat.st_size, stat.st_mtime_ns)

    def __contains__(self, key) -> bool:
        return key in self.files

    def __getitem__(self, key):
        from ..errors import InputError

        try:
            stat = os.stat(self.path)
            if (stat.st_size, stat.st_mtime_ns) != self._stamp:
                raise InputError("changed since the database was loaded; load it again", self.path)
            with np.load(self.path, allow_pickle=False) as arrays:
                return np.asarray(arrays[key])
        except OSError as exc:
            raise InputError(f"unreadable since the database was loaded ({exc.__class__.__name__})",
                             self.path) from None
