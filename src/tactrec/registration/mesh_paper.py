"""Registration onto a triangle mesh, as in the paper (Section 5.3).

Superposing (5.3.1): put ``p`` on a vertex ``v``, align the data normal with
``v``'s normal (eq. 13) and rotate the curves by ``phi`` about it.  For each
transformed data curve, fit a plane, intersect it with the mesh, and sample
the section at the data points' arc-length offsets from ``p``; the error is
the mean distance between corresponding points (eq. 15).  ``phi`` is scanned
in 10 degree steps and the smallest error kept: ``E(v)``.

Local search (5.3.2): from every candidate vertex, a greedy walk over
1-rings -- evaluate every unvisited neighbour, move to the best, stop at a
local minimum.  The registration error is the smallest over the candidates
(eq. 16).

Sections are computed on the faces near ``v`` only (within 1.5 data radii),
by intersecting the plane with every such triangle and chaining the segments
through the mesh edges they cross.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..estimation import LocalGeometry
from ..surfaces.mesh import MeshModel, resample_polyline
from ..tables import CurvatureTable
from .result import Registration, local_frame

__all__ = ["register", "DEFAULTS", "MeshSuperposition"]

DEFAULTS = {
    "delta": 0.03,          # lookup tolerance, 1/model units (the paper's P3 default, per mm)
    "phi_step": 10.0,       # degrees (Section 5.3.1)
    "max_steps": 200,       # greedy walk steps from one candidate
}


def _section_polyline(tri: np.ndarray, tri_vid: np.ndarray, origin: np.ndarray, normal: np.ndarray,
                      anchor: np.ndarray):
    """The polyline of the plane section through the triangles ``tri (k, 3, 3)``
    (vertex ids ``tri_vid (k, 3)``) that passes nearest ``anchor``.

    Returns ``(points (m, 3), closed)`` or ``None``.
    """
    d = (tri - origin) @ normal                                            # (k, 3)
    d = np.where(d == 0.0, 1e-300, d)
    crossing = [(0, 1), (1, 2), (2, 0)]
    sign_change = np.stack([d[:, a] * d[:, b] < 0 for a, b in crossing], axis=1)   # (k, 3)
    faces = np.nonzero(sign_change.sum(axis=1) == 2)[0]
    if len(faces) == 0:
        return None
    pts = []
    keys = []
    for e, (a, b) in enumerate(crossing):
        w = d[faces, a] / (d[faces, a] - d[faces, b])
        pts.append(tri[faces, a] + w[:, None] * (tri[faces, b] - tri[faces, a]))
        ka, kb = tri_vid[faces, a], tri_vid[faces, b]
        keys.append(np.minimum(ka, kb) * (1 << 32) + np.maximum(ka, kb))
    pts = np.stack(pts, axis=1)                                            # (f, 3 edges, 3)
    keys = np.stack(keys, axis=1)                                          # (f, 3)
    mask = sign_change[faces]
    seg_pts = pts[mask].reshape(-1, 2, 3)
    seg_keys = keys[mask].reshape(-1, 2)
    # chain segments through the edges they share
    owners: dict[int, list[tuple[int, int]]] = {}
    for s, (k0, k1) in enumerate(seg_keys.tolist()):
        owners.setdefault(k0, []).append((s, 0))
        owners.setdefault(k1, []).append((s, 1))
    mid = seg_pts.mean(axis=1)
    start = int(np.argmin(np.linalg.norm(mid - anchor, axis=1)))

    def walk(seg: int, end: int):
        chain = []
        seen = {seg}
        while True:
            key = int(seg_keys[seg, end])
            chain.append(seg_pts[seg, end])
            nxt = [(s, e) for s, e in owners.get(key, []) if s != seg]
            if not nxt:
                return chain, False
            seg, e = nxt[0]
            if seg in seen:
                return chain, True
            seen.add(seg)
            end = 1 - e

    forward, closed = walk(start, 1)
    if closed:
        line = [seg_pts[start, 0]] + forward
        return np.array(line), True
    backward, _ = walk(start, 0)
    line = backward[::-1] + forward
    return np.array(line), False


class MeshSuperposition:
    """E(v, phi) of Section 5.3.1 for one touch on one mesh."""

    def __init__(self, model: MeshModel, geometry: LocalGeometry, curves, *, phi_step: float):
        self.model = model
        L = local_frame(geometry.normal, geometry.directions[0])
        self.local = [(np.asarray(c, dtype=np.float64) - geometry.contact) @ L.T for c in curves]
        self.L = L
        self.contact = geometry.contact
        self.offsets = []
        for c in curves:
            c = np.asarray(c, dtype=np.float64)
            i0 = int(np.argmin(np.linalg.norm(c - geometry.contact, axis=1)))
            arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
            self.offsets.append(arc - arc[i0])
        self.radius = max(float(np.max(np.linalg.norm(x, axis=1))) for x in self.local)
        self.phis = np.deg2rad(np.arange(0.0, 360.0, phi_step))
        self._tree = cKDTree(model.vertices)
        self._cache: dict[int, tuple[float, float]] = {}

    def _frame(self, v: int) -> np.ndarray:
        f = self.model.site_frame([v])
        return np.stack([f.d1, f.d2, f.normal], axis=1)

    def _local_faces(self, v: int):
        near = self._tree.query_ball_point(self.model.vertices[v], r=1.5 * self.radius + 2 * self.model.mean_edge)
        faces = np.unique(self.model.vertex_faces[near].indices)
        vid = self.model.faces[faces]
        return self.model.vertices[vid], vid

    def error(self, v: int) -> tuple[float, float]:
        """``(E(v), phi)``: the smallest error over the phi scan at vertex ``v``."""
        if v in self._cache:
            return self._cache[v]
        tri, vid = self._local_faces(v)
        F = self._frame(v)
        q = self.model.vertices[v]
        best = (np.inf, 0.0)
        for phi in self.phis:
            c, s = np.cos(phi), np.sin(phi)
            M = F @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            total, count = 0.0, 0
            for x, off in zip(self.local, self.offsets):
                pts = x @ M.T + q
                centre = pts.mean(axis=0)
                _, _, vt = np.linalg.svd(pts - centre, full_matrices=False)
                normal, along = vt[2], vt[0]
                if (pts[-1] - pts[0]) @ along < 0:
                    along = -along
                anchor = q - ((q - centre) @ normal) * normal
                found = _section_polyline(tri, vid, centre, normal, anchor)
                if found is None:
                    total, count = np.inf, 1
                    break
                line, closed = found
                ref = resample_polyline(line, anchor, along, off, closed=closed)
                total += float(np.sum(np.linalg.norm(pts - ref, axis=1)))
                count += len(pts)
            e = total / count
            if e < best[0]:
                best = (e, float(phi))
        self._cache[v] = best
        return best

    def walk(self, v: int, *, max_steps: int) -> tuple[int, float, float]:
        """Greedy 1-ring walk from ``v`` to a local minimum of E (Section 5.3.2)."""
        indptr, indices = self.model.adjacency.indptr, self.model.adjacency.indices
        e, phi = self.error(v)
        visited = {v}
        for _ in range(max_steps):
            neighbours = [int(w) for w in indices[indptr[v]:indptr[v + 1]] if int(w) not in visited]
            if not neighbours:
                break
            visited.update(neighbours)
            scores = [self.error(w) for w in neighbours]
            j = int(np.argmin([s[0] for s in scores]))
            if scores[j][0] >= e:
                break
            v, (e, phi) = neighbours[j], scores[j]
        return v, e, phi


def register(model: MeshModel, table: CurvatureTable, geometry: LocalGeometry, points: np.ndarray, *,
             curves=None, delta: float = DEFAULTS["delta"], phi_step: float = DEFAULTS["phi_step"],
             max_steps: int = DEFAULTS["max_steps"], candidates: np.ndarray | None = None,
             **_ignored) -> Registration:
    """Register the data curves onto ``model`` from the lookup candidates (eq. 16)."""
    if curves is None:
        raise ValueError("mesh registration needs the data curves")
    idx = table.candidates(geometry.k1, geometry.k2, delta) if candidates is None else np.asarray(candidates)
    if len(idx) == 0:
        return Registration.rejection(model.name, "no candidates")
    problem = MeshSuperposition(model, geometry, curves, phi_step=phi_step)
    best = (np.inf, -1, 0.0)
    for row in idx:
        v0 = int(table.samples.sites[row, 0])
        v, e, phi = problem.walk(v0, max_steps=max_steps)
        if e < best[0]:
            best = (e, v, phi)
    e, v, phi = best
    if not np.isfinite(e):
        return Registration.rejection(model.name, "registration failed")
    F = problem._frame(v)
    c, s = np.cos(phi), np.sin(phi)
    R = F @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ problem.L
    q = model.vertices[v]
    return Registration(model=model.name, error=float(e), location=q.copy(), rotation=R,
                        translation=q - R @ geometry.contact, candidates=len(idx), site=np.array([float(v)]),
                        phi=float(phi))
