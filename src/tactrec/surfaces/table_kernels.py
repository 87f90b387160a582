"""The paper's vertex sampling (Section 5.2.1) as one compiled loop (numba; cached, no fastmath):
:func:`tactrec.surfaces.mesh_table.sample_vertices`'s rings, shrinking and marking, vertex by vertex in
the order given, so that it keeps the same vertices as the rule read step by step."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..compiled import fork_safe

__all__ = ["sample_in_order"]

fork_safe()


@njit(cache=True)
def sample_in_order(order, adj_ptr, adj_idx, vf_ptr, vf_idx, face_normals, normals, cos_theta, max_ring, min_ring):
    """The vertices kept (in ``order``, vertex indices) by the sampling rule: each vertex not yet marked
    takes its ``max_ring``-ring (breadth first over the adjacency ``adj_ptr, adj_idx``), shrunk one ring
    at a time while it is larger than ``min_ring`` and a face of it (incidence ``vf_ptr, vf_idx``) turns
    from the vertex's normal by more than ``theta`` (``dot < cos_theta``); kept, and its ring marked,
    where no vertex of the ring is marked; until half of the vertices are marked."""
    n = len(normals)
    marked = np.zeros(n, dtype=np.bool_)
    seen = np.full(n, -1, dtype=np.int64)                 # the step that reached a vertex
    queue = np.empty(n, dtype=np.int64)
    ends = np.empty(max_ring + 2, dtype=np.int64)         # the queue's end after each level
    kept = np.empty(n, dtype=np.int64)
    count, nkept = 0, 0
    for step in range(len(order)):
        if count >= n / 2:
            break
        v = order[step]
        if marked[v]:
            continue
        queue[0] = v
        seen[v] = step
        ends[0] = 1
        levels = 1
        start = 0
        for _ in range(max_ring):
            end = ends[levels - 1]
            size = end
            for q in range(start, end):
                u = queue[q]
                for a in range(adj_ptr[u], adj_ptr[u + 1]):
                    w = adj_idx[a]
                    if seen[w] != step:
                        seen[w] = step
                        queue[size] = w
                        size += 1
            ends[levels] = size
            levels += 1
            start = end
            if size == end:
                break
        ring = levels - 1
        while True:
            members = ends[ring]
            least = np.inf
            for q in range(members):
                u = queue[q]
                for a in range(vf_ptr[u], vf_ptr[u + 1]):
                    f = vf_idx[a]
                    d = face_normals[f, 0] * normals[v, 0] + face_normals[f, 1] * normals[v, 1] + \
                        face_normals[f, 2] * normals[v, 2]
                    if d < least:
                        least = d
            if ring <= min_ring or least >= cos_theta:
                break
            ring -= 1
        members = ends[ring]
        free = True
        for q in range(members):
            if marked[queue[q]]:
                free = False
                break
        if free:
            for q in range(members):
                marked[queue[q]] = True
            count += members
            kept[nkept] = v
            nkept += 1
    return kept[:nkept].copy()
