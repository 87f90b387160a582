"""The paper's lookup table on a triangle mesh (Section 5.2): sampled vertices and their principal
curvatures by paraboloid fits (eq. 14); and points sampled uniformly over a mesh's area."""

from __future__ import annotations

import numpy as np

from .base import TableSamples
from .mesh_curvature import paraboloid_curvatures

__all__ = ["sample_vertices", "vertex_curvatures", "table_samples", "area_samples"]


def sample_vertices(model, *, theta: float = np.pi / 8, max_ring: int = 6, min_ring: int = 2,
                    rng=None) -> np.ndarray:
    """The paper's vertex sampling (Section 5.2.1) of a :class:`~.mesh.MeshModel`, seeded: ``(s,)``.

    Repeat: pick a random unmarked vertex ``v``; take its 6-ring; while some
    face of the ring turns more than ``theta`` from ``v``'s normal and the
    ring is larger than 2, shrink it by one; if no vertex of the ring is
    marked, mark them all and keep ``v``.  Until half of the vertices are
    marked (or every vertex has been tried once).
    """
    from .table_kernels import sample_in_order              # numba: only once a table is made

    order = np.random.default_rng(rng).permutation(len(model.vertices))
    adjacency, incidence = model.adjacency, model.vertex_faces.tocsr()
    return sample_in_order(order.astype(np.int64), adjacency.indptr.astype(np.int64), adjacency.indices.astype(np.int64),
                           incidence.indptr.astype(np.int64), incidence.indices.astype(np.int64),
                           np.ascontiguousarray(model.face_normals, dtype=np.float64),
                           np.ascontiguousarray(model.vertex_normals, dtype=np.float64), float(np.cos(theta)),
                           int(max_ring), int(min_ring))


def vertex_curvatures(model, vertices, *, sizes=(30, 40, 50, 60, 70), ring: int = 6):
    """Principal curvatures at ``vertices (s,)`` by paraboloid fits (Section 5.2.2).

    Returns ``k1, k2`` ``(s,)`` (``k1 >= k2``), the medians over the fits to the
    ``sizes`` nearest vertices of each vertex's ``ring``-ring.
    """
    vertices = np.atleast_1d(np.asarray(vertices, dtype=np.int64))
    k1 = np.empty(len(vertices))
    k2 = np.empty(len(vertices))
    for i, v in enumerate(vertices):
        neigh = model.ring(int(v), ring)
        k1[i], k2[i] = paraboloid_curvatures(model.vertices[v], model.vertex_normals[v], model.vertices[neigh],
                                             sizes=sizes)
    return k1, k2


def table_samples(model, *, rng=0) -> TableSamples:
    """The paper's mesh table: the sampled vertices with their fitted curvatures."""
    sample = sample_vertices(model, rng=rng)
    k1, k2 = vertex_curvatures(model, sample)
    keep = np.isfinite(k1) & np.isfinite(k2)
    sample = sample[keep]
    return TableSamples(sample[:, None].astype(np.float64), model.vertices[sample], model.vertex_normals[sample],
                        k1[keep], k2[keep])


def area_samples(model, count: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points uniform over the area of the mesh ``model`` (faces chosen by area, then a point
    uniform in each, drawn from the generator ``rng``) and their faces' normals, ``(count, 3)`` each: a
    mesh's vertices need not cover its surface (a cylinder's long facets)."""
    area = model.face_areas
    face = rng.choice(len(area), size=count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    corner = model.vertices[model.faces[face]]
    points = corner[:, 0] + u[:, None] * (corner[:, 1] - corner[:, 0]) + v[:, None] * (corner[:, 2] - corner[:, 0])
    return points, model.face_normals[face]
