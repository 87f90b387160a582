"""Triangle-mesh models (paper Section 5).

Loaded with trimesh from PLY, OBJ, STL or OFF, and cleaned as a scan needs:
duplicate vertices merged, degenerate and repeated faces dropped, tiny stray
components (under 1 % of the faces) dropped, unreferenced vertices removed;
what was done is kept in :attr:`MeshModel.cleanup`.  Open (non-watertight)
meshes are fine.

* vertex normals: the normalised sum of the incident face normals (eq. 13);
* k-ring neighbourhoods from the vertex adjacency (Section 5.1.1);
* lookup table (Section 5.2): the paper's vertex sampling (theta = pi/8, the
  6-ring shrinking to 2, until half of the vertices are marked) and principal
  curvatures by paraboloid fits ``z = a x^2 + b xy + c y^2 + d x + e y + f``
  to the 30, 40, 50, 60 and 70 vertices of the 6-ring nearest to the sample,
  taking the median of ``k1`` and of ``k2`` (eq. 14).

A site on a mesh is ``[vertex]``, or ``[face, b1, b2]`` for a point inside
a face with barycentric coordinates ``(1 - b1 - b2, b1, b2)``.
"""

from __future__ import annotations

import os
from functools import cached_property
from pathlib import Path

import numpy as np
from scipy import sparse

from ..linalg import dot3, norm3
from .base import SiteFrame, SurfaceModel, TableSamples
from .mesh_field import DistanceField, build_field
from .mesh_curvature import CurvatureField, curvature_field, paraboloid_curvatures, tangents, unit_rows
from .mesh_sections import plane_section, resample_polyline, segment_distance

__all__ = ["MeshModel", "MESH_SUFFIXES", "paraboloid_curvatures", "resample_polyline"]

MESH_SUFFIXES = (".ply", ".obj", ".stl", ".off")


class MeshModel(SurfaceModel):
    """A triangle mesh (paper Section 5).

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    name, units, source, source_hash : model identity
    scale : float
        Factor already applied to the file's coordinates (recorded).
    cleanup : dict
        What the loader did to the file's mesh.
    """

    kind = "mesh"

    def __init__(self, vertices, faces, *, name: str, units: str | None = None, source: str = "<mesh>",
                 source_hash: str = "", scale: float = 1.0, cleanup: dict | None = None):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.name = name
        self.units = units
        self.source = source
        self.source_hash = source_hash
        self.scale = float(scale)
        self.cleanup = dict(cleanup or {})

    # ------------------------------------------------------------------ loading
    @classmethod
    def from_file(cls, path: str | os.PathLike, *, units: str | None = None, scale: float | None = None,
                  name: str | None = None) -> "MeshModel":
        """Load and clean a mesh file (:func:`.mesh_cleanup.read_mesh`).  ``units`` are the file's;
        ``scale`` multiplies its coordinates (e.g. 1000 with ``units="m"`` gives mm)."""
        from .mesh_cleanup import read_mesh

        vertices, faces, report, out_units, factor, digest = read_mesh(path, units=units, scale=scale)
        return cls(vertices, faces, name=name or Path(path).stem, units=out_units, source=str(path),
                   source_hash=digest, scale=factor, cleanup=report)

    # ------------------------------------------------------------------ storage
    def to_store(self) -> dict[str, np.ndarray]:
        f = self.fine_curvatures
        return {"mesh_vertices": self.vertices, "mesh_faces": self.faces,
                "mesh_units": np.array(self.units or ""), "mesh_scale": np.array(self.scale),
                "mesh_k1": f.k1, "mesh_k2": f.k2, "mesh_d1": f.d1, "mesh_normal": f.normal,
                "mesh_fit_radius": np.array(f.radius), **self.distance_field.to_store(), **self.place_rings.to_store()}

    @classmethod
    def from_store(cls, arrays, *, name: str, source: str) -> "MeshModel":
        vertices = np.asarray(arrays["mesh_vertices"], dtype=np.float64)
        faces = np.asarray(arrays["mesh_faces"], dtype=np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(vertices):
            raise ValueError("mesh faces do not index its vertices")
        units = str(arrays["mesh_units"]) or None
        model = cls(vertices, faces, name=name, units=units, source=source, scale=float(arrays["mesh_scale"]))
        field = CurvatureField(*(np.asarray(arrays[f"mesh_{k}"], dtype=np.float64) for k in ("k1", "k2", "d1", "normal")),
                               float(arrays["mesh_fit_radius"]))
        n = len(model.vertices)
        if field.k1.shape != (n,) or field.k2.shape != (n,) or field.d1.shape != (n, 3) \
                or field.normal.shape != (n, 3) or not all(np.all(np.isfinite(a)) for a in field[:4]):
            raise ValueError("the stored curvature field does not match the mesh")
        model.__dict__["fine_curvatures"] = field
        if not all(key in arrays for key in DistanceField.KEYS):
            raise ValueError("the mesh has no stored distance field")
        if "offset_radii" in arrays:                # a tip's offset fields (.mesh_offset.offset_arrays)
            radii = np.asarray(arrays["offset_radii"])
            if radii.ndim != 1 or not np.all(np.isfinite(radii) & (radii > 0)) or not all(
                    f"offset{i}_{key}" in arrays for i in range(len(radii)) for key in DistanceField.KEYS):
                raise ValueError("the stored offset fields are malformed")
        from .mesh_offset import OUTER_KEYS

        if any(key in arrays for key in OUTER_KEYS) and not all(key in arrays for key in OUTER_KEYS):
            raise ValueError("the stored outer field is malformed")
        if "rings_places" in arrays:            # the index's rows (:attr:`place_rings`)
            from .mesh_rings import PlaceRings
            model.__dict__["place_rings"] = PlaceRings.from_store(arrays, n)
        model._stored_field = arrays            # read when first used: a database loads in a moment
        return model

    # ------------------------------------------------------------------ geometry
    @cached_property
    def face_normals(self) -> np.ndarray:
        v = self.vertices[self.faces]
        return unit_rows(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]))

    @cached_property
    def vertex_normals(self) -> np.ndarray:
        """Eq. (13): normalised sum of the normals of the faces around each vertex."""
        acc = np.zeros_like(self.vertices)
        for k in range(3):
            np.add.at(acc, self.faces[:, k], self.face_normals)
        return unit_rows(acc)

    @cached_property
    def adjacency(self) -> sparse.csr_matrix:
        """Vertex adjacency (edges of the mesh), CSR."""
        f = self.faces
        i = np.concatenate([f[:, 0], f[:, 1], f[:, 2], f[:, 1], f[:, 2], f[:, 0]])
        j = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 0], f[:, 1], f[:, 2]])
        n = len(self.vertices)
        a = sparse.csr_matrix((np.ones(len(i), dtype=np.int8), (i, j)), shape=(n, n))
        a.data[:] = 1
        return a

    @cached_property
    def vertex_faces(self) -> sparse.csr_matrix:
        """Vertex-to-face incidence, CSR ``(n_vertices, n_faces)``."""
        m = len(self.faces)
        rows = self.faces.ravel()
        cols = np.repeat(np.arange(m), 3)
        return sparse.csr_matrix((np.ones(3 * m, dtype=np.int8), (rows, cols)), shape=(len(self.vertices), m))

    @cached_property
    def face_neighbours(self) -> tuple[np.ndarray, np.ndarray]:
        """Across-edge adjacency: ``(face (F, 3), edge (F, 3))``, for edge ``k`` of
        face ``f`` (corners ``k, k+1 mod 3``) the face on its other side (-1 on the
        boundary) and that face's index of the same edge.  Where more than two
        faces share an edge, the first two are paired."""
        m = len(self.faces)
        a = self.faces
        b = np.roll(self.faces, -1, axis=1)
        key = (np.minimum(a, b) * len(self.vertices) + np.maximum(a, b)).ravel()     # (3F,), edge f*3+k
        order = np.argsort(key, kind="stable")
        ks = key[order]
        pair = np.nonzero(ks[1:] == ks[:-1])[0]
        pair = pair[np.r_[True, pair[1:] != pair[:-1] + 1]] if len(pair) else pair  # first two of a run
        face = np.full(3 * m, -1, dtype=np.int64)
        edge = np.full(3 * m, -1, dtype=np.int64)
        i, j = order[pair], order[pair + 1]
        face[i], face[j] = j // 3, i // 3
        edge[i], edge[j] = j % 3, i % 3
        return face.reshape(m, 3), edge.reshape(m, 3)

    def rings(self, vertex: int, k: int) -> list[np.ndarray]:
        """Vertices at exactly 0, 1, ..., k edges from ``vertex`` (breadth first)."""
        indptr, indices = self.adjacency.indptr, self.adjacency.indices
        seen = {int(vertex)}
        levels = [np.array([vertex])]
        frontier = [int(vertex)]
        for _ in range(k):
            nxt = []
            for v in frontier:
                for w in indices[indptr[v]:indptr[v + 1]]:
                    w = int(w)
                    if w not in seen:
                        seen.add(w)
                        nxt.append(w)
            levels.append(np.array(nxt, dtype=np.int64))
            frontier = nxt
            if not nxt:
                break
        return levels

    def ring(self, vertex: int, k: int) -> np.ndarray:
        """The k-ring neighbourhood: all vertices at most ``k`` edges from ``vertex``."""
        return np.concatenate(self.rings(vertex, k))

    @cached_property
    def bounds(self) -> np.ndarray:
        """``(2, 3)``: the smallest and largest vertex coordinates."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    @cached_property
    def size(self) -> float:
        return float(norm3(self.bounds[1] - self.bounds[0]))

    @cached_property
    def face_areas(self) -> np.ndarray:
        """``(F,)`` each face's area (model units squared)."""
        v = self.vertices[self.faces]
        return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)

    @cached_property
    def search_memo(self) -> dict:
        """What a search computes of this mesh alone and would compute again for every touch (the
        field screen's place counts at a cell size), kept for the model's life."""
        return {}

    @cached_property
    def area(self) -> float:
        """The surface's area (model units squared)."""
        return float(self.face_areas.sum())

    @cached_property
    def edge_lengths(self) -> np.ndarray:
        """``(F, 3)`` lengths of each face's edges (shared edges counted once per face)."""
        f = self.faces
        return np.linalg.norm(self.vertices[f] - self.vertices[np.roll(f, 1, axis=1)], axis=-1)

    @cached_property
    def mean_edge(self) -> float:
        return float(np.mean(self.edge_lengths))

    @cached_property
    def vertex_tree(self):
        """A k-d tree (scipy ``cKDTree``) over the vertices."""
        from scipy.spatial import cKDTree

        return cKDTree(self.vertices)

    @cached_property
    def distance_field(self) -> DistanceField:
        """The truncated signed distance field the engine screens on (:mod:`.mesh_field`), its
        spacing following the mesh's mean edge.  Kept in a database."""
        stored = getattr(self, "_stored_field", None)
        if stored is not None:
            return DistanceField.from_store(stored)
        return build_field(self.vertices, self.faces, mean_edge=self.mean_edge)

    @cached_property
    def outer_field(self) -> DistanceField:
        """The field a tip's search reads beyond this field's band (:func:`.mesh_offset.outer_field`)."""
        from .mesh_offset import outer_field

        return outer_field(self)

    @cached_property
    def _offsets(self) -> dict:
        return {}

    def offset(self, radius: float):
        """The surface offset outward by ``radius`` as a search sees it (a round tip's centres:
        :class:`.mesh_offset.OffsetMesh`), made on first use and kept."""
        from .mesh_offset import OffsetMesh

        key = float(radius)
        key = next((k for k in self._offsets if np.isclose(k, key, rtol=1e-9, atol=0.0)), key)   # 0.7 x 25.4
        if key not in self._offsets:
            self._offsets[key] = OffsetMesh(self, key)
        return self._offsets[key]

    @cached_property
    def fine_curvatures(self) -> CurvatureField:
        """The :class:`~.mesh_curvature.CurvatureField` at three mean edges: every vertex's paraboloid
        fit, its principal curvatures and directions and its fitted normal.

        Kept in a database, so a recognition does not recompute it."""
        return curvature_field(self.vertices, self.vertex_normals, self.vertex_tree,
                               self.vertex_frames(np.arange(len(self.vertices))), radius=3.0 * self.mean_edge)

    @cached_property
    def place_rings(self):
        """Its places and their rings, the index's rows (:func:`tactrec.surfaces.mesh_rings.model_rings`); kept in a database."""
        from .mesh_rings import model_rings
        return model_rings(self)

    def table_samples(self, *, resolution=None, rng=0) -> TableSamples:
        """The paper's mesh table (Section 5.2): :func:`.mesh_table.table_samples`."""
        from .mesh_table import table_samples

        return table_samples(self, rng=rng)

    # ------------------------------------------------------------------ distance, sites
    @cached_property
    def _aabb(self):
        """libigl's AABB tree over the faces, for exact closest points."""
        import igl

        tree = igl.AABB()
        tree.init(self.vertices, self.faces)
        return tree

    def closest_points(self, points: np.ndarray):
        """Exact closest points on the mesh: ``(distance, face, point)`` for ``points (m, 3)``."""
        points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        sq, face, closest = self._aabb.squared_distance(self.vertices, self.faces, points)
        return np.sqrt(np.maximum(sq, 0.0)), np.asarray(face, dtype=np.int64), np.asarray(closest)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Exact distance of ``points`` (..., 3) to the mesh."""
        points = np.asarray(points, dtype=np.float64)
        return self.closest_points(points)[0].reshape(points.shape[:-1])

    def planes(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances ``(...)`` of ``points (..., 3)`` to the mesh and the unit normals ``(..., 3)``
        of the planes they are measured against.

        The normal is the direction from the closest point to the point, signed to agree with the
        closest face's normal: the face normal inside a face, the bisecting direction beside an
        edge or a corner.  It is continuous in the point, so a point whose closest face is a tie
        between two (beside a convex edge) gets the same plane whichever face the tree reports."""
        points = np.asarray(points, dtype=np.float64)
        flat = points.reshape(-1, 3)
        d, face, closest = self.closest_points(flat)
        fn = self.face_normals[face]
        diff = flat - closest
        side = np.where(np.sum(diff * fn, axis=1) < 0, -1.0, 1.0)
        tiny = 1e-12 * max(self.size, 1e-300)
        n = np.where((d > tiny)[:, None], diff * (side / np.maximum(d, tiny))[:, None], fn)
        return (side * d).reshape(points.shape[:-1]), n.reshape(points.shape)

    def site_points(self, sites) -> tuple[np.ndarray, np.ndarray]:
        """Points and outward unit normals ``(n, 3)`` of ``sites``: ``(n, 1)`` vertices or ``(n, 3)`` faces."""
        sites = np.asarray(sites, dtype=np.float64)
        if sites.ndim != 2 or sites.shape[1] not in (1, 3):
            raise ValueError("a mesh site is [vertex] or [face, b1, b2]")
        if sites.shape[1] == 3:
            b = np.stack([1.0 - sites[:, 1] - sites[:, 2], sites[:, 1], sites[:, 2]], axis=1)
            c = self.faces[sites[:, 0].astype(np.int64)]
            point = sum(b[:, k, None] * self.vertices[c[:, k]] for k in range(3))
            normal = sum(b[:, k, None] * self.vertex_normals[c[:, k]] for k in range(3))
            return point, unit_rows(normal)
        v = sites[:, 0].astype(np.int64)
        wrong = v[(v < 0) | (v >= len(self.vertices))]
        if len(wrong):
            raise ValueError(f"vertex {wrong[0]} is not in the mesh (0..{len(self.vertices) - 1})")
        return self.vertices[v], self.vertex_normals[v]

    def site_frame(self, site) -> SiteFrame:
        site = np.atleast_1d(np.asarray(site, dtype=np.float64))
        point, normal = self.site_points(site[None])
        d1, d2 = tangents(normal)
        return SiteFrame(site, point[0], d1[0], d2[0], normal[0])

    def vertex_frames(self, vertices) -> np.ndarray:
        """``(n, 3, 3)`` frames of ``vertices (n,)``, columns ``[d1 d2 n]`` as in :meth:`site_frame`."""
        normal = self.vertex_normals[np.asarray(vertices, dtype=np.int64)]
        d1, d2 = tangents(normal)
        return np.stack([d1, d2, normal], axis=2)

    def locate(self, point) -> np.ndarray:
        """``[face, b1, b2]`` of the surface point nearest to ``point``."""
        _, face, closest = self.closest_points(np.asarray(point, dtype=float)[None])
        a, b, c = self.vertices[self.faces[int(face[0])]]
        e0, e1, w = b - a, c - a, closest[0] - a                 # Cramer's rule, as trimesh's barycentric
        d00, d01, d11, d0w, d1w = dot3(e0, e0), dot3(e0, e1), dot3(e1, e1), dot3(e0, w), dot3(e1, w)
        det = d00 * d11 - d01 * d01
        return np.array([float(face[0]), (d11 * d0w - d01 * d1w) / det, (d00 * d1w - d01 * d0w) / det])

    def random_sites(self, count: int, *, rng=None) -> np.ndarray:
        """Random vertices (the paper's P3 places touches on vertices)."""
        rng = np.random.default_rng(rng)
        return rng.choice(len(self.vertices), size=count, replace=count > len(self.vertices))[:, None].astype(float)

    def plane_section(self, site, tangent, *, spacing: float, count: int) -> np.ndarray:
        """Points of the mesh's section by the plane through the site spanned by
        its normal and ``tangent``, at equal arc length, centred on the site."""
        frame = self.site_frame(site)
        p, n = frame.point, frame.normal
        t = unit_rows(np.asarray(tangent, dtype=float) - dot3(tangent, n) * n)
        m = np.cross(n, t)
        section = plane_section(self.vertices, self.faces, p, m)
        if section is None:
            raise ValueError("the plane does not cut the mesh")
        best, best_d = None, np.inf
        for entity in section.entities:          # open polylines too (``discrete`` holds closed loops only)
            line = np.asarray(entity.discrete(section.vertices), dtype=float)
            if len(line) < 2:
                continue
            d = segment_distance(line, p)
            if d < best_d:
                best, best_d = line, d
        if best is None or best_d > 1e-6 * max(self.size, 1e-300) + 1e-9:
            raise ValueError("the plane section does not pass through the site")
        offsets = (np.arange(count) - (count - 1) / 2.0) * spacing
        return resample_polyline(best, p, t, offsets, closed=bool(np.allclose(best[0], best[-1])), strict=True)


