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

How it is computed.  Everything for a batch of vertices at once: for each
vertex and each of the ``phi x curves`` planes, the section starts at the
crossing segment nearest the anchor (the vertex projected on the plane)
among the faces within two rings of the vertex, and is followed both ways,
triangle by triangle through the across-edge adjacency, until it has
covered the data's arc length (or the mesh ends, or it has taken four times
as many steps as that length needs at the median edge length).  Which way
along the section is "forward" is decided by its first few points, not by
the start segment alone, which has no length where the plane passes through
a mesh vertex.  The data's arc-length offsets are then looked up by binary
search.  The greedy walks from all candidates advance in step, each step
evaluating every new neighbour in one batch.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from ..estimation import LocalGeometry
from ..linalg import compose, dot3, eigh, gram, rotate, times
from ..surfaces.mesh import MeshModel
from ..tables import CurvatureTable
from ..units import conversion
from .result import Registration, local_frame, rotations_z

__all__ = ["register", "DEFAULTS", "MeshSuperposition", "default_delta"]

DEFAULTS = {
    "delta": None,          # lookup tolerance, 1/model units; None: the paper's 0.03 /mm in the model's units
    "phi_step": 10.0,       # degrees (Section 5.3.1)
    "max_steps": 200,       # greedy walk steps from one candidate
}

_EDGES = ((0, 1), (1, 2), (2, 0))


def _edge_point(Y: np.ndarray, d: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Where edge ``e`` (corners ``e, e+1 mod 3``) of triangles ``Y (..., 3, 3)`` crosses
    the plane, from the corners' signed distances ``d (..., 3)``; ``e`` is ``(...)``."""
    e = np.asarray(e)
    f = (e + 1) % 3
    da = np.take_along_axis(d, e[..., None], axis=-1)
    db = np.take_along_axis(d, f[..., None], axis=-1)
    ya = np.take_along_axis(Y, e[..., None, None], axis=-2)[..., 0, :]
    yb = np.take_along_axis(Y, f[..., None, None], axis=-2)[..., 0, :]
    return ya + (da / (da - db)) * (yb - ya)


class MeshSuperposition:
    """E(v, phi) of Section 5.3.1 for one touch on one mesh.

    Parameters
    ----------
    model : MeshModel
    geometry : LocalGeometry
        Contact, normal and first principal direction of the touch.
    curves : sequence of (n_i, 3) arrays
        The data curves, data frame.
    phi_step : float
        Degrees between the rotations tried about the normal.
    batch : int
        Vertices evaluated together (memory grows with it).
    """

    def __init__(self, model: MeshModel, geometry: LocalGeometry, curves, *, phi_step: float, batch: int = 8):
        self.model = model
        self.batch = int(batch)
        L = local_frame(geometry.normal, geometry.directions[0])
        self.L = L
        self.contact = geometry.contact
        local, offsets, centres, normals, alongs = [], [], [], [], []
        for c in curves:
            c = np.asarray(c, dtype=np.float64)
            x = times(c - geometry.contact, L.T)
            i0 = int(np.argmin(np.linalg.norm(c - geometry.contact, axis=1)))
            arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
            centre = x.mean(axis=0)
            _, v = eigh(gram((x - centre)[None])[0])                  # the scatter's axes, largest last
            along = v[:, 2] if dot3(x[-1] - x[0], v[:, 2]) >= 0 else -v[:, 2]
            local.append(x)
            offsets.append(arc - arc[i0])
            centres.append(centre)
            normals.append(v[:, 0])
            alongs.append(along)
        self.radius = max(float(np.max(np.linalg.norm(x, axis=1))) for x in local)
        self.phis = np.deg2rad(np.arange(0.0, 360.0, phi_step))
        R = rotations_z(self.phis)                                               # (f, 3, 3)
        ncurves = len(local)
        # planes p = f * ncurves + i, in the frame of the vertex
        self.normals = np.einsum("fij,cj->fci", R, np.array(normals)).reshape(-1, 3)     # (P, 3)
        self.alongs = np.einsum("fij,cj->fci", R, np.array(alongs)).reshape(-1, 3)
        centres = np.einsum("fij,cj->fci", R, np.array(centres)).reshape(-1, 3)
        self.heights = np.sum(self.normals * centres, axis=1)                            # (P,)
        self.anchors = self.heights[:, None] * self.normals                               # origin projected
        self.points = np.einsum("fij,nj->fni", R, np.concatenate(local))                 # (f, n, 3)
        self.point_curve = np.concatenate([np.full(len(x), i) for i, x in enumerate(local)])
        self.point_offset = np.concatenate(offsets)
        self.ncurves = ncurves
        # arc length each section must reach, per plane; steps across triangles to get there
        reach = np.array([np.max(np.abs(self.point_offset[self.point_curve == i])) for i in range(ncurves)])
        self.reach = np.tile(reach, len(self.phis)) + 1e-9                                  # (P,)
        median_edge = float(np.median(model.edge_lengths))
        self.max_steps_along = int(np.ceil(4.0 * float(reach.max()) / max(median_edge, 1e-12))) + 16
        self.sign_reach = 2.0 * model.mean_edge
        self._cache: dict[int, tuple[float, float]] = {}

    @property
    def evaluated(self) -> int:
        """How many vertices ``E`` has been computed at."""
        return len(self._cache)

    def _frame(self, v: int) -> np.ndarray:
        return self.model.vertex_frames([v])[0]

    # -- E(v) for a batch of vertices ------------------------------------------------------

    def _start_segments(self, V: np.ndarray, normal: np.ndarray, offset: np.ndarray, anchor: np.ndarray):
        """Where each section starts: for the planes ``normal . x = offset``
        (``(n, P, 3)``, ``(n, P)``) of vertex ``V[o]``, the crossing segment
        nearest the plane's ``anchor`` among the faces within two rings of the
        vertex.  Returns ``face (n, P)`` (-1 if none), its end points ``A, B
        (n, P, 3)`` and the edges they lie on, ``edge_A, edge_B (n, P)``."""
        model = self.model
        fans = self._fans(V)
        counts = np.diff(fans.indptr)
        owner = np.repeat(np.arange(len(V)), counts)
        faces = fans.indices
        Y = model.vertices[model.faces[faces]]                                          # (k, 3, 3)
        d = np.einsum("kcj,kpj->kpc", Y, normal[owner]) - offset[owner][:, :, None]      # (k, P, 3)
        d[d == 0.0] = 1e-300
        pos = d > 0
        change = np.stack([pos[..., 0] != pos[..., 1], pos[..., 1] != pos[..., 2], pos[..., 2] != pos[..., 0]], -1)
        crossed = change.any(axis=-1)                                                   # (k, P)
        e_a = np.where(change[..., 0], 0, 1)                                            # (0,1) or else (1,2)
        e_b = np.where(change[..., 2], 2, 1)                                            # (2,0) or else (1,2)
        A = _edge_point(Y[:, None], d, e_a)
        B = _edge_point(Y[:, None], d, e_b)
        gap = np.where(crossed, np.sum((0.5 * (A + B) - anchor[owner]) ** 2, axis=-1), np.inf)   # (k, P)
        n, P = normal.shape[:2]
        best = np.full((n, P), np.inf)
        np.minimum.at(best, owner, gap)
        k_idx, p_idx = np.nonzero((gap == best[owner]) & np.isfinite(gap))
        o_idx = owner[k_idx]
        face = np.full((n, P), -1, dtype=np.int64)
        pa, pb = np.zeros((n, P, 3)), np.zeros((n, P, 3))
        ea, eb = np.zeros((n, P), dtype=np.int64), np.zeros((n, P), dtype=np.int64)
        face[o_idx, p_idx] = faces[k_idx]
        pa[o_idx, p_idx], pb[o_idx, p_idx] = A[k_idx, p_idx], B[k_idx, p_idx]
        ea[o_idx, p_idx], eb[o_idx, p_idx] = e_a[k_idx, p_idx], e_b[k_idx, p_idx]
        return face, pa, pb, ea, eb

    def _fans(self, V: np.ndarray) -> sparse.csr_matrix:
        """Faces touching the 1-ring of each vertex of ``V``, CSR ``(n, F)``."""
        model = self.model
        rows = model.adjacency[V]
        rows = rows + sparse.csr_matrix((np.ones(len(V)), (np.arange(len(V)), V)), shape=rows.shape)
        fans = (rows @ model.vertex_faces).tocsr()
        fans.sort_indices()
        return fans

    def _march(self, normal, offset, face, edge, point, arc, need):
        """Follow plane sections across the mesh, one triangle per step.

        Each walker enters ``face (w,)`` through its edge ``edge (w,)`` at
        ``point (w, 3)``, ``arc (w,)`` along the section, and goes on until its
        arc length reaches ``need (w,)`` or the mesh ends.  Returns the points
        ``(w, s, 3)`` and arc lengths ``(w, s)`` it passed (``inf`` after the end).
        """
        model = self.model
        nb_face, nb_edge = model.face_neighbours
        face, edge = face.copy(), edge.copy()
        steps = self.max_steps_along
        pts = np.zeros((len(face), steps + 1, 3))
        arcs = np.full((len(face), steps + 1), np.inf)
        pts[:, 0], arcs[:, 0] = point, arc
        cur_pt, cur_arc = point.copy(), arc.copy()
        active = np.nonzero((face >= 0) & (arc < need))[0]
        for step in range(1, steps + 1):
            if len(active) == 0:
                break
            f, k = face[active], edge[active]
            Y = model.vertices[model.faces[f]]                                          # (a, 3, 3)
            d = np.einsum("acj,aj->ac", Y, normal[active]) - offset[active][:, None]
            d[d == 0.0] = 1e-300
            pos = d > 0
            rows = np.arange(len(active))
            e1 = (k + 1) % 3
            out = np.where(pos[rows, e1] != pos[rows, (k + 2) % 3], e1, (k + 2) % 3)    # the other crossed edge
            p = _edge_point(Y, d, out)
            cur_arc[active] += np.linalg.norm(p - cur_pt[active], axis=1)
            cur_pt[active] = p
            pts[active, step], arcs[active, step] = p, cur_arc[active]
            face[active], edge[active] = nb_face[f, out], nb_edge[f, out]
            active = active[(face[active] >= 0) & (cur_arc[active] < need[active])]
        return pts, arcs

    def _errors(self, V: np.ndarray) -> np.ndarray:
        """``E(v, phi) (n, f)`` for vertices ``V (n,)``."""
        model = self.model
        n, P, nphi = len(V), len(self.normals), len(self.phis)
        frames = model.vertex_frames(V)                                                  # (n, 3, 3)
        q = model.vertices[V]
        normal = np.einsum("oij,pj->opi", frames, self.normals)                         # planes, model frame
        offset = self.heights[None, :] + np.einsum("opi,oi->op", normal, q)
        anchor = np.einsum("oij,pj->opi", frames, self.anchors) + q[:, None, :]
        face, A, B, ea, eb = self._start_segments(V, normal, offset, anchor)
        found = face >= 0
        AB = B - A
        t = np.clip(np.sum((anchor - A) * AB, axis=-1) / np.maximum(np.sum(AB * AB, axis=-1), 1e-300), 0.0, 1.0)
        cut = A + t[..., None] * AB                                                      # the anchor, on the section
        # two walkers per plane, leaving the start face through A (end 0) and through B (end 1)
        nb_face, nb_edge = model.face_neighbours
        f0 = np.where(found, face, 0)[..., None]
        start_edge = np.stack([ea, eb], axis=-1)                                         # (n, P, 2)
        next_face = np.where(found[..., None], nb_face[f0, start_edge], -1)
        next_edge = nb_edge[f0, start_edge]
        first = np.stack([A, B], axis=2)                                                # (n, P, 2, 3)
        first_arc = np.linalg.norm(first - cut[:, :, None, :], axis=-1)
        need = np.broadcast_to(self.reach[None, :, None], (n, P, 2))
        pts, arcs = self._march(np.repeat(normal, 2, axis=1).reshape(-1, 3), np.repeat(offset, 2, axis=1).ravel(),
                                next_face.ravel(), next_edge.ravel(), first.reshape(-1, 3), first_arc.ravel(),
                                need.ravel())
        pts = np.concatenate([np.repeat(cut, 2, axis=1).reshape(-1, 1, 3), pts], axis=1)
        arcs = np.concatenate([np.zeros((len(arcs), 1)), arcs], axis=1)
        # which end runs along the data curve: decided by the section's first few points, not by
        # the cut segment alone, which has no length where the plane passes through a mesh vertex
        along = np.repeat(np.einsum("oij,pj->opi", frames, self.alongs), 2, axis=1).reshape(-1, 1, 3)
        close = (arcs <= self.sign_reach)[..., None]
        ahead = np.sum(np.where(close, (pts - pts[:, :1]) * along, 0.0), axis=(1, 2)).reshape(n, P, 2)
        b_forward = ahead[..., 1] >= ahead[..., 0]                                       # (n, P)
        # every data point's offset, looked up on its (vertex, plane, end) walker
        plane = np.arange(nphi)[:, None] * self.ncurves + self.point_curve[None, :]     # (f, pts)
        end = (self.point_offset > 0)[None, None, :] == b_forward[:, plane]             # (n, f, pts)
        row = ((np.arange(n)[:, None, None] * P + plane[None]) * 2 + end).ravel()
        target = np.broadcast_to(np.abs(self.point_offset), end.shape).ravel()
        steps = arcs.shape[1]
        width = float(self.reach.max()) * 4.0 + 1.0                                     # > every finite arc
        flat = (np.arange(len(arcs))[:, None] * width + np.minimum(arcs, width * 0.75)).ravel()   # sorted
        i = np.searchsorted(flat, row * width + target, side="right") - 1                # row * steps + index
        j = np.minimum(i + 1, row * steps + steps - 1)
        a_i, a_j = arcs.ravel()[i], arcs.ravel()[j]
        ok = np.isfinite(a_j) & (a_j > a_i)                                              # else: the section ended
        frac = np.where(ok, (target - a_i) / np.where(ok, a_j - a_i, 1.0), 0.0).clip(0.0, 1.0)
        flat_pts = pts.reshape(-1, 3)
        ref = (flat_pts[i] + frac[:, None] * (flat_pts[j] - flat_pts[i])).reshape(n, nphi, -1, 3)
        data = rotate(frames[:, None, None], self.points[None]) + q[:, None, None, :]
        err = np.linalg.norm(data - ref, axis=-1).mean(axis=-1)                         # (n, f)
        missing = ~found[:, plane].all(axis=-1)
        return np.where(missing, np.inf, err)

    def errors(self, vertices) -> list[tuple[float, float]]:
        """``[(E(v), phi)]``: the smallest error over the phi scan at each vertex."""
        vertices = [int(v) for v in vertices]
        todo = np.array(sorted({v for v in vertices if v not in self._cache}), dtype=np.int64)
        for k in range(0, len(todo), self.batch):
            V = todo[k:k + self.batch]
            E = self._errors(V)
            best = np.argmin(E, axis=1)
            for v, b, e in zip(V.tolist(), best.tolist(), E[np.arange(len(V)), best].tolist()):
                self._cache[v] = (e, float(self.phis[b]))
        return [self._cache[v] for v in vertices]

    def error(self, v: int) -> tuple[float, float]:
        """``(E(v), phi)`` at one vertex."""
        return self.errors([v])[0]

    def walks(self, starts, *, max_steps: int) -> list[tuple[int, float, float, set]]:
        """Greedy 1-ring walks (Section 5.3.2) from every vertex of ``starts``, in step.

        Returns ``[(vertex, E, phi, evaluated)]`` per start: the local minimum
        reached and the set of vertices the walk evaluated.
        """
        indptr, indices = self.model.adjacency.indptr, self.model.adjacency.indices
        starts = [int(v) for v in starts]
        state = [[v, *s, {v}] for v, s in zip(starts, self.errors(starts))]
        active = list(range(len(state)))
        for _ in range(max_steps):
            if not active:
                break
            todo = {}
            for w in active:
                v, _, _, seen = state[w]
                todo[w] = [int(u) for u in indices[indptr[v]:indptr[v + 1]] if int(u) not in seen]
            self.errors([u for us in todo.values() for u in us])
            still = []
            for w in active:
                us = todo[w]
                if not us:
                    continue
                st = state[w]
                st[3].update(us)
                scores = [self._cache[u] for u in us]
                j = int(np.argmin([s[0] for s in scores]))
                if scores[j][0] >= st[1]:
                    continue
                st[0], (st[1], st[2]) = us[j], scores[j]
                still.append(w)
            active = still
        return [tuple(s) for s in state]

    def walk(self, v: int, *, max_steps: int) -> tuple[int, float, float]:
        """Greedy 1-ring walk from ``v`` to a local minimum of E (Section 5.3.2)."""
        return self.walks([v], max_steps=max_steps)[0][:3]

    def rotation(self, v: int, phi: float) -> np.ndarray:
        """``data2model`` rotation of the superposition at vertex ``v``, angle ``phi``."""
        return compose(compose(self._frame(v), rotations_z(np.array([phi]))[0]), self.L)


#: the paper's lookup tolerance for meshes (P3), per millimetre
PAPER_DELTA_PER_MM = 0.03


def default_delta(model: MeshModel) -> float:
    """The paper's 0.03 /mm in ``model``'s units (per model unit if it has none)."""
    return PAPER_DELTA_PER_MM * (conversion(model.units, "mm") if model.units else 1.0)


def register(model: MeshModel, table: CurvatureTable, geometry: LocalGeometry, points: np.ndarray, *,
             curves=None, delta: float | None = DEFAULTS["delta"], phi_step: float = DEFAULTS["phi_step"],
             max_steps: int = DEFAULTS["max_steps"], candidates: np.ndarray | None = None,
             **_ignored) -> Registration:
    """Register the data curves onto ``model`` from the lookup candidates (eq. 16).

    ``delta`` is in 1/model units; by default the paper's 0.03 /mm converted
    to them (30 /m for a mesh in metres)."""
    if curves is None:
        raise ValueError("mesh registration needs the data curves")
    if delta is None:
        delta = default_delta(model)
    idx = table.candidates(geometry.k1, geometry.k2, delta) if candidates is None else np.asarray(candidates)
    if len(idx) == 0:
        return Registration.unfitted(model.name, "no candidates")
    problem = MeshSuperposition(model, geometry, curves, phi_step=phi_step)
    if problem.radius > model.size:
        return Registration.unfitted(model.name, "the touch is larger than the model")
    found = problem.walks(table.samples.sites[idx, 0].astype(np.int64), max_steps=max_steps)
    v, e, phi, _ = min(found, key=lambda w: w[1])
    if not np.isfinite(e):
        return Registration.unfitted(model.name, "registration failed")
    R = problem.rotation(v, phi)
    q = model.vertices[v]
    return Registration(model=model.name, error=float(e), location=q.copy(), rotation=R,
                        translation=q - rotate(R, geometry.contact), candidates=len(idx), site=np.array([float(v)]),
                        phi=float(phi))
