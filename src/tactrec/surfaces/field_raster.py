"""Compiled sampling of a mesh's signed distance at its field's bricks (numba; cached, no fastmath).

A brick's samples (:class:`tactrec.surfaces.mesh_field.DistanceField`) need
the exact distance only where the surface lies within ``reach`` (the band,
and a tip's offset); everywhere else a sample is clipped to the band and only
its side counts.  So each face is swept over the samples of the bricks near
it (those within ``reach`` of its bounding box) rather than each sample
searching the whole mesh:

* **Distance**: per sample, the least over the faces listed for its brick of
  the distance to the face's closest point (Ericson's regions: a corner, an
  edge or the inside).  A face within ``reach`` of a sample is listed for
  the sample's brick, so where the least is within ``reach`` it is exact.
* **Side**: by the angle-weighted pseudonormal of the closest feature
  (Baerentzen and Aanaes, 2005), as libigl signs: the face's normal inside
  it, the mean of its faces' normals on an edge, the angle-weighted mean at
  a corner.  Of faces equally near, the first (lowest index) decides.
* **Beyond ``reach``**: a sample with no face within ``reach`` takes the side
  of a neighbouring sample (a cell away) that has one.  The distance moves by
  at most a cell between neighbours, so both lie at least ``reach`` less a
  cell from the surface: no surface passes between them, and on a closed mesh
  they lie on the same side.  The bricks are visited in parallel, each on its
  own samples, its faces in order: the same bits on every CPU.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..compiled import fork_safe

__all__ = ["brick_distances"]

fork_safe()


@njit(cache=True, nogil=True)
def _closest(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz, out):
    """The closest point on triangle ``abc`` to ``p`` into ``out[:3]``; returns its region: 0 inside,
    1-3 a corner (a, b, c), 4-6 an edge (bc, ca, ab: opposite corner a, b, c)."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        out[0], out[1], out[2] = ax, ay, az
        return 1
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        out[0], out[1], out[2] = bx, by, bz
        return 2
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        out[0], out[1], out[2] = ax + v * abx, ay + v * aby, az + v * abz
        return 6
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        out[0], out[1], out[2] = cx, cy, cz
        return 3
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        out[0], out[1], out[2] = ax + w * acx, ay + w * acy, az + w * acz
        return 5
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        out[0], out[1], out[2] = bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz)
        return 4
    total = va + vb + vc
    if not total > 0.0:                  # a face of no area: the tests above leave no region to it
        out[0], out[1], out[2] = ax, ay, az
        return 1
    v = vb / total
    w = vc / total
    out[0], out[1], out[2] = ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w
    return 0


@njit(cache=True, nogil=True)
def _span(u, v, w, base, h, reach, brick):
    """The samples ``(first, last)`` along one axis of a brick starting at ``base`` that lie within
    ``reach`` of the face's extent ``u, v, w`` on that axis (first > last: none)."""
    lo = int(np.ceil((min(u, v, w) - reach - base) / h - 1e-9))
    hi = int(np.floor((max(u, v, w) + reach - base) / h + 1e-9))
    return max(0, lo), min(brick, hi)


@njit(cache=True, parallel=True)
def brick_distances(vertices, faces, face_normals, vertex_normals, edge_normals, face_edges, origin, h, reach,
                    blocks, starts, listed, brick):
    """The signed distances ``(k, brick + 1, brick + 1, brick + 1)`` at the samples of the bricks
    ``blocks (k, 3)`` of a grid at ``origin`` with spacing ``h``, each brick's faces ``listed[starts[i]:
    starts[i + 1]]`` in increasing order (module text); ``face_edges (f, 3)``: the edge opposite each
    corner of each face, a row of ``edge_normals``.  Beyond ``reach`` a sample is ``+-inf``."""
    k = blocks.shape[0]
    n = brick + 1
    out = np.empty((k, n, n, n))
    for i in prange(k):
        best = np.full((n, n, n), np.inf)
        side = np.zeros((n, n, n), dtype=np.int8)
        c = np.empty(3)
        gx, gy, gz = blocks[i, 0] * brick, blocks[i, 1] * brick, blocks[i, 2] * brick
        bx0, by0, bz0 = origin[0] + gx * h, origin[1] + gy * h, origin[2] + gz * h
        for q in range(starts[i], starts[i + 1]):
            f = listed[q]
            a, b, cc = faces[f, 0], faces[f, 1], faces[f, 2]
            x0, x1 = _span(vertices[a, 0], vertices[b, 0], vertices[cc, 0], bx0, h, reach, brick)
            y0, y1 = _span(vertices[a, 1], vertices[b, 1], vertices[cc, 1], by0, h, reach, brick)
            z0, z1 = _span(vertices[a, 2], vertices[b, 2], vertices[cc, 2], bz0, h, reach, brick)
            for x in range(x0, x1 + 1):
                px = origin[0] + (gx + x) * h
                for y in range(y0, y1 + 1):
                    py = origin[1] + (gy + y) * h
                    for z in range(z0, z1 + 1):
                        pz = origin[2] + (gz + z) * h
                        region = _closest(px, py, pz, vertices[a, 0], vertices[a, 1], vertices[a, 2],
                                          vertices[b, 0], vertices[b, 1], vertices[b, 2],
                                          vertices[cc, 0], vertices[cc, 1], vertices[cc, 2], c)
                        dx, dy, dz = px - c[0], py - c[1], pz - c[2]
                        d2 = dx * dx + dy * dy + dz * dz
                        if d2 < best[x, y, z]:
                            best[x, y, z] = d2
                            if region == 0:
                                nx, ny, nz = face_normals[f, 0], face_normals[f, 1], face_normals[f, 2]
                            elif region <= 3:
                                v = faces[f, region - 1]
                                nx, ny, nz = vertex_normals[v, 0], vertex_normals[v, 1], vertex_normals[v, 2]
                            else:
                                e = face_edges[f, region - 4]
                                nx, ny, nz = edge_normals[e, 0], edge_normals[e, 1], edge_normals[e, 2]
                            side[x, y, z] = 1 if dx * nx + dy * ny + dz * nz >= 0.0 else -1
        limit = reach * reach
        for x in range(n):
            for y in range(n):
                for z in range(n):
                    if best[x, y, z] >= limit:
                        side[x, y, z] = 0
        _spread(side, n)
        for x in range(n):
            for y in range(n):
                for z in range(n):
                    s = 1.0 if side[x, y, z] >= 0 else -1.0
                    out[i, x, y, z] = s * (np.sqrt(best[x, y, z]) if best[x, y, z] < limit else np.inf)
    return out


@njit(cache=True, nogil=True)
def _spread(side, n):
    """Each sample of no side (0) takes that of a neighbour (a cell away along an axis) that has one,
    in sweeps until none changes (module text); a brick with none keeps 0, read as outside."""
    changed = True
    while changed:
        changed = False
        for x in range(n):
            for y in range(n):
                for z in range(n):
                    if side[x, y, z] != 0:
                        continue
                    s = 0
                    if x > 0 and side[x - 1, y, z] != 0:
                        s = side[x - 1, y, z]
                    elif x + 1 < n and side[x + 1, y, z] != 0:
                        s = side[x + 1, y, z]
                    elif y > 0 and side[x, y - 1, z] != 0:
                        s = side[x, y - 1, z]
                    elif y + 1 < n and side[x, y + 1, z] != 0:
                        s = side[x, y + 1, z]
                    elif z > 0 and side[x, y, z - 1] != 0:
                        s = side[x, y, z - 1]
                    elif z + 1 < n and side[x, y, z + 1] != 0:
                        s = side[x, y, z + 1]
                    if s != 0:
                        side[x, y, z] = s
                        changed = True
