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

import hashlib
import os
from functools import cached_property
from pathlib import Path

import numpy as np
from scipy import sparse

from ..errors import InputError
from .base import SiteFrame, SurfaceModel, TableSamples

__all__ = ["MeshModel", "MESH_SUFFIXES", "paraboloid_curvatures", "resample_polyline"]

MESH_SUFFIXES = (".ply", ".obj", ".stl", ".off")
STRAY_FRACTION = 0.01


def _unit_rows(a: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(a, axis=-1, keepdims=True)
    return a / np.where(norm > 0, norm, 1.0)


def _tangents(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``d1, d2 (n, 3)`` completing unit ``normal (n, 3)`` to right-handed frames:
    ``d1`` is the coordinate axis least aligned with the normal, projected."""
    helper = np.eye(3)[np.argmin(np.abs(normal), axis=1)]
    d1 = _unit_rows(helper - np.sum(helper * normal, axis=1, keepdims=True) * normal)
    return d1, np.cross(normal, d1)


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
        """Load and clean a mesh file.  ``units`` are the file's; ``scale``
        multiplies its coordinates (e.g. 1000 with ``units="m"`` gives mm)."""
        import trimesh

        from ..units import UNITS, unit_scale

        path = Path(path)
        if not path.is_file():
            raise InputError("no such file", path)
        if units is not None:
            try:
                unit_scale(units)
            except ValueError as exc:
                raise InputError(str(exc), path) from None
        if scale is not None and not (np.isfinite(scale) and scale > 0):
            raise InputError(f"scale must be a positive number, got {scale!r}", path)
        blob = path.read_bytes()
        if not blob.strip():
            raise InputError("empty file", path)
        try:
            mesh = trimesh.load(path, force="mesh", process=False)
        except Exception as exc:  # trimesh raises many kinds on a broken file
            raise InputError(f"cannot read mesh ({exc.__class__.__name__}: {str(exc)[:120]})", path) from None
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0 or len(mesh.vertices) < 3:
            raise InputError("no triangles in the file", path)
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        if not np.all(np.isfinite(vertices)):
            raise InputError("vertex coordinates are not finite", path)
        vertices, faces, report = clean_mesh(vertices, np.asarray(mesh.faces, dtype=np.int64))
        if len(faces) == 0:
            raise InputError("degenerate mesh: no triangle with a non-zero area", path)
        factor = 1.0 if scale is None else float(scale)
        out_units = units
        if scale is not None and units is not None:
            # name the units the scaled coordinates are in, when it is a known one
            target = unit_scale(units) / factor
            out_units = next((u for u, s in UNITS.items() if np.isclose(s, target, rtol=1e-9)), None)
        return cls(vertices * factor, faces, name=name or path.stem, units=out_units, source=str(path),
                   source_hash=hashlib.sha256(blob).hexdigest(), scale=factor, cleanup=report)

    # ------------------------------------------------------------------ storage
    def to_store(self) -> dict[str, np.ndarray]:
        k1, k2, d1, radius = self.fine_curvatures
        return {"mesh_vertices": self.vertices, "mesh_faces": self.faces,
                "mesh_units": np.array(self.units or ""), "mesh_scale": np.array(self.scale),
                "mesh_k1": k1, "mesh_k2": k2, "mesh_d1": d1, "mesh_fit_radius": np.array(radius)}

    @classmethod
    def from_store(cls, arrays, *, name: str, source: str) -> "MeshModel":
        vertices = np.asarray(arrays["mesh_vertices"], dtype=np.float64)
        faces = np.asarray(arrays["mesh_faces"], dtype=np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(vertices):
            raise ValueError("mesh faces do not index its vertices")
        units = str(arrays["mesh_units"]) or None
        model = cls(vertices, faces, name=name, units=units, source=source, scale=float(arrays["mesh_scale"]))
        if "mesh_k1" in arrays:
            field = (np.asarray(arrays["mesh_k1"], dtype=np.float64), np.asarray(arrays["mesh_k2"], dtype=np.float64),
                     np.asarray(arrays["mesh_d1"], dtype=np.float64), float(arrays["mesh_fit_radius"]))
            n = len(model.vertices)
            if field[0].shape != (n,) or field[1].shape != (n,) or field[2].shape != (n, 3) \
                    or not all(np.all(np.isfinite(a)) for a in field[:3]):
                raise ValueError("the stored curvature field does not match the mesh")
            model.__dict__["fine_curvatures"] = field
        return model

    # ------------------------------------------------------------------ geometry
    @cached_property
    def face_normals(self) -> np.ndarray:
        v = self.vertices[self.faces]
        return _unit_rows(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]))

    @cached_property
    def vertex_normals(self) -> np.ndarray:
        """Eq. (13): normalised sum of the normals of the faces around each vertex."""
        acc = np.zeros_like(self.vertices)
        for k in range(3):
            np.add.at(acc, self.faces[:, k], self.face_normals)
        return _unit_rows(acc)

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
        return float(np.linalg.norm(self.bounds[1] - self.bounds[0]))

    @cached_property
    def edge_lengths(self) -> np.ndarray:
        """``(F, 3)`` lengths of each face's edges (shared edges counted once per face)."""
        f = self.faces
        return np.linalg.norm(self.vertices[f] - self.vertices[np.roll(f, 1, axis=1)], axis=-1)

    @cached_property
    def mean_edge(self) -> float:
        return float(np.mean(self.edge_lengths))

    # ------------------------------------------------------------------ table
    def sample_vertices(self, *, theta: float = np.pi / 8, max_ring: int = 6, min_ring: int = 2,
                        rng=None) -> np.ndarray:
        """The paper's vertex sampling (Section 5.2.1), seeded.

        Repeat: pick a random unmarked vertex ``v``; take its 6-ring; while some
        face of the ring turns more than ``theta`` from ``v``'s normal and the
        ring is larger than 2, shrink it by one; if no vertex of the ring is
        marked, mark them all and keep ``v``.  Until half of the vertices are
        marked (or every vertex has been tried once).
        """
        rng = np.random.default_rng(rng)
        n = len(self.vertices)
        marked = np.zeros(n, dtype=bool)
        count = 0
        samples = []
        cos_theta = np.cos(theta)
        vf = self.vertex_faces
        normals = self.vertex_normals
        fn = self.face_normals
        for v in rng.permutation(n):
            if count >= n / 2:
                break
            if marked[v]:
                continue
            levels = self.rings(int(v), max_ring)
            ring = len(levels) - 1
            while True:
                members = np.concatenate(levels[: ring + 1])
                faces = np.unique(vf[members].indices)
                if ring <= min_ring or np.min(fn[faces] @ normals[v]) >= cos_theta:
                    break
                ring -= 1
            if not marked[members].any():
                marked[members] = True
                count += len(members)
                samples.append(int(v))
        return np.array(samples, dtype=np.int64)

    def vertex_curvatures(self, vertices, *, sizes=(30, 40, 50, 60, 70), ring: int = 6):
        """Principal curvatures at ``vertices`` by paraboloid fits (Section 5.2.2).

        Returns ``k1, k2`` (``k1 >= k2``), the medians over the fits to the
        ``sizes`` nearest vertices of each vertex's ``ring``-ring.
        """
        vertices = np.atleast_1d(np.asarray(vertices, dtype=np.int64))
        k1 = np.empty(len(vertices))
        k2 = np.empty(len(vertices))
        for i, v in enumerate(vertices):
            neigh = self.ring(int(v), ring)
            k1[i], k2[i] = paraboloid_curvatures(self.vertices[v], self.vertex_normals[v], self.vertices[neigh],
                                                 sizes=sizes)
        return k1, k2

    def curvature_field(self, *, radius: float | None = None, most: int = 96
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Principal curvatures and the first principal direction at every vertex.

        One weighted paraboloid fit (eq. 14) per vertex to the vertices within
        ``radius`` (default three mean edges; at most ``most`` of them, at least
        the nearest 12) whose normals agree with its own, so a thin wall's
        other side is left out; all vertices at once.  Returns ``k1, k2 (V,)``
        (``k1 >= k2``, outward normals) and ``d1 (V, 3)``, a unit tangent.
        """
        radius = 3.0 * self.mean_edge if radius is None else float(radius)
        count = min(most, len(self.vertices))
        dist, idx = self.vertex_tree.query(self.vertices, k=count)
        frames = self.vertex_frames(np.arange(len(self.vertices)))                     # (V, 3, 3) [t1 t2 n]
        local = np.einsum("vkj,vji->vki", self.vertices[idx] - self.vertices[:, None, :], frames)
        agree = np.einsum("vkj,vj->vk", self.vertex_normals[idx], self.vertex_normals) > 0.5
        weight = (agree & ((dist <= radius) | (np.arange(count) < 12))).astype(float)
        k1, k2, (u, v) = quadric_curvatures(local, weight)
        t1, t2, n = frames[:, :, 0], frames[:, :, 1], frames[:, :, 2]
        d1 = u[:, None] * t1 + v[:, None] * t2 + 0.0 * n
        return k1, k2, _unit_rows(d1)

    @cached_property
    def vertex_tree(self):
        """A k-d tree (scipy ``cKDTree``) over the vertices."""
        from scipy.spatial import cKDTree

        return cKDTree(self.vertices)

    @cached_property
    def fine_curvatures(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """:meth:`curvature_field` at three mean edges, and that radius: ``k1, k2 (V,), d1 (V, 3), radius``.

        Kept in a database, so a recognition does not recompute it."""
        radius = 3.0 * self.mean_edge
        return (*self.curvature_field(radius=radius), radius)

    def table_samples(self, *, resolution=None, rng=0) -> TableSamples:
        """The paper's mesh table: sampled vertices with fitted curvatures."""
        sample = self.sample_vertices(rng=rng)
        k1, k2 = self.vertex_curvatures(sample)
        keep = np.isfinite(k1) & np.isfinite(k2)
        sample = sample[keep]
        return TableSamples(sample[:, None].astype(np.float64), self.vertices[sample], self.vertex_normals[sample],
                            k1[keep], k2[keep])

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

    @cached_property
    def _trimesh(self):
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False)

    def site_frame(self, site) -> SiteFrame:
        site = np.atleast_1d(np.asarray(site, dtype=np.float64))
        if len(site) == 1:
            v = int(site[0])
            if not 0 <= v < len(self.vertices):
                raise ValueError(f"vertex {v} is not in the mesh (0..{len(self.vertices) - 1})")
            point, normal = self.vertices[v], self.vertex_normals[v]
        elif len(site) == 3:
            f = int(site[0])
            b = np.array([1.0 - site[1] - site[2], site[1], site[2]])
            corners = self.faces[f]
            point = b @ self.vertices[corners]
            normal = _unit_rows(b @ self.vertex_normals[corners])
        else:
            raise ValueError("a mesh site is [vertex] or [face, b1, b2]")
        d1, d2 = _tangents(normal[None])
        return SiteFrame(site, point, d1[0], d2[0], normal)

    def vertex_frames(self, vertices) -> np.ndarray:
        """``(n, 3, 3)`` frames of ``vertices (n,)``, columns ``[d1 d2 n]`` as in :meth:`site_frame`."""
        normal = self.vertex_normals[np.asarray(vertices, dtype=np.int64)]
        d1, d2 = _tangents(normal)
        return np.stack([d1, d2, normal], axis=2)

    def locate(self, point) -> np.ndarray:
        """``[face, b1, b2]`` of the surface point nearest to ``point``."""
        import trimesh

        _, face, closest = self.closest_points(np.asarray(point, dtype=float)[None])
        tri = self.vertices[self.faces[int(face[0])]]
        bary = trimesh.triangles.points_to_barycentric(tri[None], closest)[0]
        return np.array([float(face[0]), bary[1], bary[2]])

    def random_sites(self, count: int, *, rng=None) -> np.ndarray:
        """Random vertices (the paper's P3 places touches on vertices)."""
        rng = np.random.default_rng(rng)
        return rng.choice(len(self.vertices), size=count, replace=count > len(self.vertices))[:, None].astype(float)

    def plane_section(self, site, tangent, *, spacing: float, count: int) -> np.ndarray:
        """Points of the mesh's section by the plane through the site spanned by
        its normal and ``tangent``, at equal arc length, centred on the site."""
        frame = self.site_frame(site)
        p, n = frame.point, frame.normal
        t = _unit_rows(np.asarray(tangent, dtype=float) - (np.asarray(tangent, dtype=float) @ n) * n)
        m = np.cross(n, t)
        section = self._trimesh.section(plane_origin=p, plane_normal=m)
        if section is None:
            raise ValueError("the plane does not cut the mesh")
        best, best_d = None, np.inf
        for entity in section.entities:          # open polylines too (``discrete`` holds closed loops only)
            line = np.asarray(entity.discrete(section.vertices), dtype=float)
            if len(line) < 2:
                continue
            d = _segment_distance(line, p)
            if d < best_d:
                best, best_d = line, d
        if best is None or best_d > 1e-6 * max(self.size, 1e-300) + 1e-9:
            raise ValueError("the plane section does not pass through the site")
        offsets = (np.arange(count) - (count - 1) / 2.0) * spacing
        return resample_polyline(best, p, t, offsets, closed=bool(np.allclose(best[0], best[-1])), strict=True)


def _project_on_polyline(line: np.ndarray, p: np.ndarray) -> tuple[int, float, float]:
    """Nearest segment ``k`` of ``line`` to ``p``, the parameter ``t`` in [0, 1]
    of the nearest point on it, and the distance."""
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0.0, 1.0)
    dist = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
    k = int(np.argmin(dist))
    return k, float(t[k]), float(dist[k])


def _segment_distance(line: np.ndarray, p: np.ndarray) -> float:
    """Distance from ``p`` to the polyline ``line``."""
    return _project_on_polyline(line, p)[2]


def resample_polyline(line: np.ndarray, anchor: np.ndarray, along: np.ndarray, offsets: np.ndarray, *,
                      closed: bool, strict: bool = False) -> np.ndarray:
    """Points of ``line`` at arc-length ``offsets`` from the point nearest ``anchor``,
    positive offsets in the direction of ``along``.

    On a closed loop the offsets wrap around; on an open line they stop at its
    ends, or (``strict``) raise ``ValueError`` where they would run past them.
    """
    # repeated points (a plane through a mesh vertex) would leave the direction undefined
    line = line[np.r_[True, np.linalg.norm(np.diff(line, axis=0), axis=1) > 0]]
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    k, t, _ = _project_on_polyline(line, anchor)
    direction = 1.0 if (line[k + 1] - line[k]) @ along >= 0 else -1.0
    targets = arc[k] + t * seg[k] + direction * np.asarray(offsets, dtype=float)
    if closed:
        targets = np.mod(targets, arc[-1])
    elif strict and (targets.min() < -1e-9 or targets.max() > arc[-1] + 1e-9):
        raise ValueError("a section curve runs off the edge of the mesh")
    return np.stack([np.interp(targets, arc, line[:, i]) for i in range(3)], axis=1)


def clean_mesh(vertices: np.ndarray, faces: np.ndarray):
    """Merge duplicate vertices, drop degenerate, repeated and out-of-range
    faces and stray components (under 1 % of the faces), remove unreferenced
    vertices.  Returns ``vertices, faces, report``."""
    report = {"vertices_in": int(len(vertices)), "faces_in": int(len(faces))}
    bad = (faces < 0) | (faces >= len(vertices))
    if bad.any():
        faces = faces[~bad.any(axis=1)]
        report["faces_out_of_range"] = int(bad.any(axis=1).sum())
    scale = float(np.ptp(vertices, axis=0).max()) or 1.0
    key = np.round(vertices / (scale * 1e-9)).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    report["duplicate_vertices_merged"] = int(len(vertices) - len(first))
    vertices = vertices[first]
    faces = inverse[faces]
    tri = vertices[faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    degenerate = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2]) \
        | (area2 <= 1e-12 * scale * scale)
    report["degenerate_faces_dropped"] = int(degenerate.sum())
    faces = faces[~degenerate]
    _, unique = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    report["repeated_faces_dropped"] = int(len(faces) - len(unique))
    faces = faces[np.sort(unique)]
    if len(faces):
        # components by shared vertices
        n = len(vertices)
        m = len(faces)
        inc = sparse.csr_matrix((np.ones(3 * m), (np.repeat(np.arange(m), 3), faces.ravel())), shape=(m, n))
        graph = sparse.bmat([[None, inc], [inc.T, None]]).tocsr()
        ncomp, labels = sparse.csgraph.connected_components(graph, directed=False)
        face_labels = labels[:m]
        counts = np.bincount(face_labels, minlength=ncomp)
        keep_comp = counts >= max(1, STRAY_FRACTION * m)
        keep = keep_comp[face_labels]
        report["stray_components_dropped"] = int(np.sum((counts > 0) & ~keep_comp))
        report["stray_faces_dropped"] = int((~keep).sum())
        faces = faces[keep]
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used) - 1
    report["unreferenced_vertices_removed"] = int((~used).sum())
    vertices = vertices[used]
    faces = remap[faces]
    report["vertices"] = int(len(vertices))
    report["faces"] = int(len(faces))
    return vertices, faces, report


def quadric_curvatures(local: np.ndarray, weight: np.ndarray):
    """Principal curvatures at the origin of ``z = a x^2 + b xy + c y^2 + d x + e y + f``
    fitted (weighted least squares) to points ``local (n, k, 3)`` given in
    frames ``(t1, t2, N)``, ``n`` fits at once; ``weight (n, k)``.

    Returns ``k1, k2 (n,)`` (``k1 >= k2``; a surface bending away from ``N``
    has negative curvature) and the ``(t1, t2)`` components ``(2, n)`` of the
    first principal direction, projected on the tangent plane and unit.
    """
    x, y, z = local[..., 0], local[..., 1], local[..., 2]
    scale = np.maximum(np.max(np.hypot(x, y) * (weight > 0), axis=-1), 1e-12)[..., None]
    X, Y = x / scale, y / scale
    A = np.stack([X * X, X * Y, Y * Y, X, Y, np.ones_like(X)], axis=-1)               # (n, k, 6)
    Aw = A * weight[..., None]
    coef = np.linalg.solve(np.einsum("vki,vkj->vij", Aw, A) + 1e-12 * np.eye(6),
                           np.einsum("vki,vk->vi", Aw, z)[..., None])[..., 0]
    s = scale[..., 0]
    a, b, c = coef[..., 0] / s**2, coef[..., 1] / s**2, coef[..., 2] / s**2
    d, e = coef[..., 3] / s, coef[..., 4] / s
    w = np.sqrt(1 + d * d + e * e)
    E, F, G = 1 + d * d, d * e, 1 + e * e
    L, M, N = 2 * a / w, b / w, 2 * c / w
    det = E * G - F * F
    H = (E * N - 2 * F * M + G * L) / (2 * det)
    K = (L * N - M * M) / det
    root = np.sqrt(np.maximum(H * H - K, 0.0))
    k1, k2 = H + root, H - root
    # (II - k1 I) v = 0, v from whichever row is larger; (1, 0) where the point is umbilic
    r1 = np.stack([-(M - k1 * F), L - k1 * E])
    r2 = np.stack([N - k1 * G, -(M - k1 * F)])
    v = np.where(np.sum(r1 * r1, axis=0) >= np.sum(r2 * r2, axis=0), r1, r2)
    norm = np.hypot(v[0], v[1])
    v = np.where(norm > 1e-300, v / np.where(norm > 1e-300, norm, 1.0), np.array([[1.0], [0.0]]) * np.ones_like(norm))
    return k1, k2, v


def paraboloid_curvatures(center: np.ndarray, normal: np.ndarray, neighbours: np.ndarray, *,
                          sizes=(30, 40, 50, 60, 70)) -> tuple[float, float]:
    """Median principal curvatures of paraboloid fits (eq. 14) at ``center``.

    ``neighbours`` (m, 3) are expressed in the frame (t1, t2, n) at ``center``
    and sorted by distance; ``z = a x^2 + b xy + c y^2 + d x + e y + f`` is
    fitted to the nearest ``s`` of them for each ``s`` in ``sizes`` (fewer if
    the ring is smaller, at least 6); the principal curvatures of each fit at
    the origin (Monge patch, ``k = c'' . n``) are reduced by medians, ``k1``
    and ``k2`` separately.
    """
    n = normal / np.linalg.norm(normal)
    (t1,), (t2,) = _tangents(n[None])
    rel = neighbours - center
    order = np.argsort(np.linalg.norm(rel, axis=1))
    local = rel[order] @ np.stack([t1, t2, n]).T
    counts = [s for s in sorted(set(min(s, len(local)) for s in sizes)) if s >= 6]
    # a fit needs six independent monomials among its points
    counts = [s for s in counts
              if np.linalg.matrix_rank(np.stack([local[:s, 0] ** 2, local[:s, 0] * local[:s, 1], local[:s, 1] ** 2,
                                                 local[:s, 0], local[:s, 1], np.ones(s)], axis=1)) == 6]
    if not counts:
        return float("nan"), float("nan")
    weight = (np.arange(len(local))[None, :] < np.array(counts)[:, None]).astype(float)
    k1, k2, _ = quadric_curvatures(np.broadcast_to(local, (len(counts), *local.shape)), weight)
    arr = np.stack([k1, k2], axis=1)
    return float(np.median(arr[:, 0])), float(np.median(arr[:, 1]))
