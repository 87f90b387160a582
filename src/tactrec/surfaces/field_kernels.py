"""Compiled sampling of a mesh's distance field (numba; cached, no fastmath).

The field is the sparse brick grid of :class:`tactrec.surfaces.mesh_field.DistanceField`:
``index (bx, by, bz) int32`` names the brick of each block of :data:`BRICK` cells
(-1: none, every cell at least the truncation away), ``bricks (nb, BRICK + 1,
BRICK + 1, BRICK + 1) int16`` hold the signed distance at the cells' corners
in units of ``quantum``; a point outside every brick is ``truncation`` away.
A field's ``shift`` is subtracted from every sample: the field of the
surface offset outward by that much, read from the same bricks
(:meth:`tactrec.surfaces.mesh_field.DistanceField.shifted`).  Each sample is
the same trilinear interpolation in a fixed order, in double precision: the
same bits on every CPU.  The engine's screen and field steps
(:mod:`tactrec.engine.kernels`) read the field through these.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..compiled import fork_safe

__all__ = ["BRICK", "field_lookup", "field_gradient"]

fork_safe()

#: cells along a field brick's edge (a brick stores BRICK + 1 samples a side, so that no lookup
#: crosses bricks)
BRICK = 8


@njit(cache=True, nogil=True)
def _cell(index, origin, inv_h, x, y, z):
    """The brick of the cell holding one point and the point's place in it: ``(b, lx, ly, lz, fx, fy,
    fz)``, ``b`` -1 outside every brick."""
    gx = (x - origin[0]) * inv_h
    gy = (y - origin[1]) * inv_h
    gz = (z - origin[2]) * inv_h
    if not (gx >= 0.0 and gy >= 0.0 and gz >= 0.0):          # also NaN
        return -1, 0, 0, 0, 0.0, 0.0, 0.0
    ix = int(gx)
    iy = int(gy)
    iz = int(gz)
    bx = ix // BRICK
    by = iy // BRICK
    bz = iz // BRICK
    if bx >= index.shape[0] or by >= index.shape[1] or bz >= index.shape[2]:
        return -1, 0, 0, 0, 0.0, 0.0, 0.0
    return index[bx, by, bz], ix - bx * BRICK, iy - by * BRICK, iz - bz * BRICK, gx - ix, gy - iy, gz - iz


@njit(cache=True, nogil=True)
def _sample(index, bricks, origin, inv_h, quantum, truncation, shift, x, y, z):
    """Signed distance at one point by trilinear interpolation, less ``shift``, within ``truncation``
    (``truncation`` outside every brick)."""
    b, lx, ly, lz, fx, fy, fz = _cell(index, origin, inv_h, x, y, z)
    if b < 0:
        return truncation
    c = bricks[b]
    c00 = c[lx, ly, lz] * (1.0 - fx) + c[lx + 1, ly, lz] * fx
    c10 = c[lx, ly + 1, lz] * (1.0 - fx) + c[lx + 1, ly + 1, lz] * fx
    c01 = c[lx, ly, lz + 1] * (1.0 - fx) + c[lx + 1, ly, lz + 1] * fx
    c11 = c[lx, ly + 1, lz + 1] * (1.0 - fx) + c[lx + 1, ly + 1, lz + 1] * fx
    c0 = c00 * (1.0 - fy) + c10 * fy
    c1 = c01 * (1.0 - fy) + c11 * fy
    return _within((c0 * (1.0 - fz) + c1 * fz) * quantum - shift, truncation)


@njit(cache=True, nogil=True)
def _within(d, truncation):
    """``d`` clipped to ``[-truncation, truncation]`` (a shifted field's band is narrower than its
    samples')."""
    if d > truncation:
        return truncation
    if d < -truncation:
        return -truncation
    return d


@njit(cache=True, nogil=True)
def _sample_gradient(index, bricks, origin, inv_h, quantum, truncation, shift, x, y, z, out):
    """Signed distance at one point less ``shift`` and its gradient (into ``out (3,)``; zero outside
    every brick, and where the distance is clipped to ``truncation``)."""
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    b, lx, ly, lz, fx, fy, fz = _cell(index, origin, inv_h, x, y, z)
    if b < 0:
        return truncation
    c = bricks[b]
    v000 = float(c[lx, ly, lz])
    v100 = float(c[lx + 1, ly, lz])
    v010 = float(c[lx, ly + 1, lz])
    v110 = float(c[lx + 1, ly + 1, lz])
    v001 = float(c[lx, ly, lz + 1])
    v101 = float(c[lx + 1, ly, lz + 1])
    v011 = float(c[lx, ly + 1, lz + 1])
    v111 = float(c[lx + 1, ly + 1, lz + 1])
    c00 = v000 * (1.0 - fx) + v100 * fx
    c10 = v010 * (1.0 - fx) + v110 * fx
    c01 = v001 * (1.0 - fx) + v101 * fx
    c11 = v011 * (1.0 - fx) + v111 * fx
    c0 = c00 * (1.0 - fy) + c10 * fy
    c1 = c01 * (1.0 - fy) + c11 * fy
    s = quantum * inv_h
    out[0] = (((v100 - v000) * (1.0 - fy) + (v110 - v010) * fy) * (1.0 - fz)
              + ((v101 - v001) * (1.0 - fy) + (v111 - v011) * fy) * fz) * s
    out[1] = (c10 - c00) * (1.0 - fz) * s + (c11 - c01) * fz * s
    out[2] = (c1 - c0) * s
    d = (c0 * (1.0 - fz) + c1 * fz) * quantum - shift
    if abs(d) >= truncation:
        out[0] = 0.0
        out[1] = 0.0
        out[2] = 0.0
        return _within(d, truncation)
    return d


@njit(cache=True, parallel=True)
def field_lookup(index, bricks, origin, inv_h, quantum, truncation, shift, points):
    """Signed, truncated distances ``(m,)`` of ``points (m, 3)``."""
    out = np.empty(points.shape[0])
    for i in prange(points.shape[0]):
        out[i] = _sample(index, bricks, origin, inv_h, quantum, truncation, shift,
                         points[i, 0], points[i, 1], points[i, 2])
    return out


@njit(cache=True, parallel=True)
def field_gradient(index, bricks, origin, inv_h, quantum, truncation, shift, points):
    """Signed, truncated distances ``(m,)`` of ``points (m, 3)`` and their gradients ``(m, 3)``."""
    d = np.empty(points.shape[0])
    g = np.zeros((points.shape[0], 3))
    for i in prange(points.shape[0]):
        d[i] = _sample_gradient(index, bricks, origin, inv_h, quantum, truncation, shift,
                                points[i, 0], points[i, 1], points[i, 2], g[i])
    return d, g
