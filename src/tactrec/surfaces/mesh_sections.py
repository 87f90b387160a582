"""Plane sections of a triangle mesh, resampled at equal arc length (simulated touches, Section 5.4)."""

from __future__ import annotations

import numpy as np

from ..linalg import dot3

__all__ = ["resample_polyline", "segment_distance"]


def _project_on_polyline(line: np.ndarray, p: np.ndarray) -> tuple[int, float, float]:
    """Nearest segment ``k`` of ``line`` to ``p``, the parameter ``t`` in [0, 1]
    of the nearest point on it, and the distance."""
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0.0, 1.0)
    dist = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
    k = int(np.argmin(dist))
    return k, float(t[k]), float(dist[k])


def segment_distance(line: np.ndarray, p: np.ndarray) -> float:
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
    direction = 1.0 if dot3(line[k + 1] - line[k], along) >= 0 else -1.0
    targets = arc[k] + t * seg[k] + direction * np.asarray(offsets, dtype=float)
    if closed:
        targets = np.mod(targets, arc[-1])
    elif strict and (targets.min() < -1e-9 or targets.max() > arc[-1] + 1e-9):
        raise ValueError("a section curve runs off the edge of the mesh")
    return np.stack([np.interp(targets, arc, line[:, i]) for i in range(3)], axis=1)


def plane_section(vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, normal: np.ndarray):
    """The section of the mesh ``vertices, faces`` by the plane through ``origin`` with ``normal``: a
    trimesh ``Path3D``, or None where the plane misses the mesh.

    The cases and segments of trimesh's ``mesh_plane`` (a vertex within ``1e-8`` of the plane is on
    it), with the vertices' heights and the edges' crossings in element-wise arithmetic: trimesh
    takes them from the BLAS, whose kernels round differently on different CPUs."""
    from trimesh.grouping import unique_value_in_row
    from trimesh.path.exchange.misc import lines_to_path
    from trimesh.path.path import Path3D

    origin, normal = np.asarray(origin, dtype=np.float64), np.asarray(normal, dtype=np.float64)
    dots = dot3(vertices - origin, normal)
    signs = np.zeros(len(vertices), dtype=np.int8)
    signs[dots < -1e-8] = -1
    signs[dots > 1e-8] = 1
    signs = signs[faces]
    coded = np.full(len(faces), 14, dtype=np.int8)
    for i, column in enumerate(np.sort(signs, axis=1).T):
        coded += column << 3 - i
    basic, one_vertex, one_edge = np.isin(coded, (4, 12)), coded == 8, coded == 16

    def crossing(edges):                         # where the edges (2, k) cross the plane
        a, b = vertices[edges[0]], vertices[edges[1]]
        t = dot3(origin - a, normal) / dot3(b - a, normal)
        return a + t[:, None] * (b - a)

    f, s = faces[basic], signs[basic]
    alone = unique_value_in_row(s, unique=[-1, 1])
    edges = np.column_stack((f[alone], f[np.roll(alone, 1, axis=1)], f[alone], f[np.roll(alone, 2, axis=1)]))
    lines = [crossing(edges.reshape(-1, 2).T).reshape(-1, 2, 3)]
    f, s = faces[one_vertex], signs[one_vertex]
    lines.append(np.column_stack((vertices[f[s == 0]], crossing(f[s != 0].reshape(-1, 2).T))).reshape(-1, 2, 3))
    f, s = faces[one_edge], signs[one_edge]
    lines.append(vertices[f[s == 0].reshape(-1, 2)])
    lines = np.vstack(lines)
    return Path3D(**lines_to_path(lines)) if len(lines) else None
