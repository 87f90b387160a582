"""Plane sections walked from a vertex across a mesh's faces, read at set arc lengths (numba; cached,
no fastmath).

A touch's curve is the section of the surface by a plane through the contact that holds its normal
(Section 2 of the paper), traced from the contact.  :func:`section_heights` traces the same curves
from a mesh's vertices: for each vertex and direction ``d`` in its tangent plane, the section by the
plane holding the vertex's normal ``n`` and ``d``, walked face to face across the edges it crosses,
away from the vertex along ``d``; at each arc length asked for, the height of the curve over the
vertex's tangent plane, ``(x - p) . n``.  A walk that reaches the mesh's boundary (or an edge of more
than two faces) before an arc length leaves NaN there.

A vertex on the cutting plane is counted on its positive side, one rule for every face, so that the
plane never passes through a vertex as the walk sees it: each face it enters has exactly one edge to
leave by.  Every walk is independent and adds its segments in order, in double precision, so the
heights are the same on every CPU.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..compiled import fork_safe

__all__ = ["section_heights"]

fork_safe()

#: faces a walk may cross before it is given up (a walk of a few millimetres crosses tens)
MAX_FACES = 100_000


@njit(cache=True)
def _side(x, p, w):
    return (x[0] - p[0]) * w[0] + (x[1] - p[1]) * w[1] + (x[2] - p[2]) * w[2]


@njit(cache=True)
def _first_face(V, F, vf_ptr, vf_idx, iv, p, w, d):
    """The face of vertex ``iv``'s fan that the section leaves ``p`` into along ``d``: the face whose
    opposite edge the plane crosses furthest along ``d``; its index, the local index of that edge and
    the crossing.  -1 where no face lies ahead."""
    best, bf, bk = 0.0, -1, -1
    bx = np.zeros(3)
    for q in range(vf_ptr[iv], vf_ptr[iv + 1]):
        f = vf_idx[q]
        k0 = 0
        for k in range(3):
            if F[f, k] == iv:
                k0 = k
        a, b = F[f, (k0 + 1) % 3], F[f, (k0 + 2) % 3]
        sa, sb = _side(V[a], p, w), _side(V[b], p, w)
        if (sa >= 0.0) == (sb >= 0.0):
            continue
        t = sa / (sa - sb)
        x = V[a] + t * (V[b] - V[a])
        r = x - p
        length = np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
        if length <= 0.0:
            continue
        c = (r[0] * d[0] + r[1] * d[1] + r[2] * d[2]) / length
        if c > best:
            best, bf, bk = c, f, (k0 + 1) % 3
            bx[:] = x
    return bf, bk, bx


@njit(parallel=True, cache=True)
def _walk(V, F, nb_face, nb_edge, vf_ptr, vf_idx, places, normals, directions, arcs, out):
    P, A, J = directions.shape[0], directions.shape[1], arcs.shape[0]
    for i in prange(P * A):
        pi, ai = i // A, i % A
        iv = places[pi]
        p, n, d = V[iv], normals[pi], directions[pi, ai]
        for j in range(J):
            out[pi, ai, j] = np.nan
        w = np.empty(3)
        w[0] = n[1] * d[2] - n[2] * d[1]
        w[1] = n[2] * d[0] - n[0] * d[2]
        w[2] = n[0] * d[1] - n[1] * d[0]
        f, kx, y = _first_face(V, F, vf_ptr, vf_idx, iv, p, w, d)
        if f < 0:
            continue
        x = p.copy()
        s, j, crossed = 0.0, 0, 0
        while j < J and crossed < MAX_FACES:
            crossed += 1
            seg = y - x
            length = np.sqrt(seg[0] * seg[0] + seg[1] * seg[1] + seg[2] * seg[2])
            while j < J and s + length >= arcs[j]:
                u = (arcs[j] - s) / length if length > 0.0 else 0.0
                out[pi, ai, j] = (x[0] + u * seg[0] - p[0]) * n[0] + (x[1] + u * seg[1] - p[1]) * n[1] \
                    + (x[2] + u * seg[2] - p[2]) * n[2]
                j += 1
            s += length
            g, kin = nb_face[f, kx], nb_edge[f, kx]
            if j >= J or g < 0:
                break
            v0, v1, v2 = F[g, kin], F[g, (kin + 1) % 3], F[g, (kin + 2) % 3]
            s0, s1, s2 = _side(V[v0], p, w), _side(V[v1], p, w), _side(V[v2], p, w)
            if (s1 >= 0.0) != (s2 >= 0.0):
                kx, qa, qb, ta, tb = (kin + 1) % 3, v1, v2, s1, s2
            elif (s2 >= 0.0) != (s0 >= 0.0):
                kx, qa, qb, ta, tb = (kin + 2) % 3, v2, v0, s2, s0
            else:
                break
            t = ta / (ta - tb)
            x = y
            y = V[qa] + t * (V[qb] - V[qa])
            f = g
    return out


def section_heights(model, places: np.ndarray, normals: np.ndarray, directions: np.ndarray,
                    arcs: np.ndarray) -> np.ndarray:
    """Heights ``(P, A, J)`` over each place's tangent plane of the mesh's section in each of its
    directions, at the arc lengths ``arcs (J,)`` (increasing, model units): ``places (P,)`` vertex
    indices, ``normals (P, 3)`` and ``directions (P, A, 3)`` unit vectors, each direction in its
    place's tangent plane."""
    face, edge = model.face_neighbours
    incidence = model.vertex_faces.tocsr()
    out = np.empty((len(places), directions.shape[1], len(arcs)))
    if len(places) == 0:
        return out
    return _walk(model.vertices, model.faces, face, edge, incidence.indptr.astype(np.int64),
                 incidence.indices.astype(np.int64), np.ascontiguousarray(places, dtype=np.int64),
                 np.ascontiguousarray(normals, dtype=np.float64), np.ascontiguousarray(directions, dtype=np.float64),
                 np.ascontiguousarray(arcs, dtype=np.float64), out)
