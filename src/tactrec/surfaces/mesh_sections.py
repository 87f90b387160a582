"""Plane sections of a triangle mesh, resampled at equal arc length (simulated touches, Section 5.4)."""

from __future__ import annotations

import numpy as np

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
    direction = 1.0 if (line[k + 1] - line[k]) @ along >= 0 else -1.0
    targets = arc[k] + t * seg[k] + direction * np.asarray(offsets, dtype=float)
    if closed:
        targets = np.mod(targets, arc[-1])
    elif strict and (targets.min() < -1e-9 or targets.max() > arc[-1] + 1e-9):
        raise ValueError("a section curve runs off the edge of the mesh")
    return np.stack([np.interp(targets, arc, line[:, i]) for i in range(3)], axis=1)


