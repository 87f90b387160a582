"""Principal curvatures on a triangle mesh by paraboloid fits (paper Section 5.2.2, eq. 14)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..linalg import gram, norm3, solve_spd, times

__all__ = ["quadric_curvatures", "paraboloid_curvatures", "tangents", "unit_rows", "CurvatureField",
           "curvature_field"]


class CurvatureField(NamedTuple):
    """One paraboloid fit per vertex (eq. 14) at one scale (:func:`curvature_field`).

    k1, k2 : (V,) principal curvatures, ``k1 >= k2`` (outward normals)
    d1 : (V, 3) unit first principal direction, in the fitted tangent plane
    normal : (V, 3) unit normal of the fitted paraboloid at the vertex
    radius : float, the fit's radius (model units)
    """

    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    normal: np.ndarray
    radius: float


def unit_rows(a: np.ndarray) -> np.ndarray:
    """Rows of ``a (..., 3)`` scaled to unit length (zero rows stay zero)."""
    norm = np.linalg.norm(a, axis=-1, keepdims=True)
    return a / np.where(norm > 0, norm, 1.0)


def tangents(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``d1, d2 (n, 3)`` completing unit ``normal (n, 3)`` to right-handed frames:
    ``d1`` is the coordinate axis least aligned with the normal, projected."""
    helper = np.eye(3)[np.argmin(np.abs(normal), axis=1)]
    d1 = unit_rows(helper - np.sum(helper * normal, axis=1, keepdims=True) * normal)
    return d1, np.cross(normal, d1)


def quadric_curvatures(local: np.ndarray, weight: np.ndarray):
    """Principal curvatures at the origin of ``z = a x^2 + b xy + c y^2 + d x + e y + f``
    fitted (weighted least squares) to points ``local (n, k, 3)`` given in
    frames ``(t1, t2, N)``, ``n`` fits at once; ``weight (n, k)``.

    Returns ``k1, k2 (n,)`` (``k1 >= k2``; a surface bending away from ``N``
    has negative curvature), the ``(t1, t2)`` components ``(2, n)`` of the
    first principal direction, projected on the tangent plane and unit, and
    the fitted slopes ``(d, e)`` ``(2, n)``: the fitted surface's normal at the
    origin is ``(-d, -e, 1)`` normalised.  The solve is element-wise
    (:func:`tactrec.linalg.solve_spd`): the same on every CPU.
    """
    x, y, z = local[..., 0], local[..., 1], local[..., 2]
    scale = np.maximum(np.max(np.hypot(x, y) * (weight > 0), axis=-1), 1e-12)[..., None]
    X, Y = x / scale, y / scale
    A = np.stack([X * X, X * Y, Y * Y, X, Y, np.ones_like(X)], axis=-1)               # (n, k, 6)
    root_w = np.sqrt(weight)
    AtA, Atz = gram(A * root_w[..., None], z * root_w)
    coef = solve_spd(AtA + 1e-12 * np.eye(6), Atz)
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
    return k1, k2, v, np.stack([d, e])


def fitted_frame(frames: np.ndarray, direction: np.ndarray, slope: np.ndarray):
    """The fitted surface's normal and first principal direction ``(n, 3)`` each, from frames
    ``(n, 3, 3)`` (columns ``t1 t2 N``), the direction's ``(t1, t2)`` components ``(2, n)`` and
    the slopes ``(2, n)`` of :func:`quadric_curvatures`."""
    t1, t2, n = frames[..., 0], frames[..., 1], frames[..., 2]
    (u, v), (d, e) = direction, slope
    normal = unit_rows(n - d[:, None] * t1 - e[:, None] * t2)
    d1 = unit_rows(u[:, None] * t1 + v[:, None] * t2 + (d * u + e * v)[:, None] * n)
    return normal, d1


def curvature_field(vertices: np.ndarray, normals: np.ndarray, tree, frames: np.ndarray, *, radius: float,
                    most: int = 96) -> CurvatureField:
    """One weighted paraboloid fit (eq. 14) per vertex to the vertices within ``radius`` (at most
    ``most`` of them, at least the nearest 12) whose normals agree with its own (so a thin wall's
    other side is left out), all at once.  ``frames (V, 3, 3)`` are the vertex frames (columns
    ``t1 t2 n``) and ``tree`` a k-d tree over ``vertices``."""
    count = min(most, len(vertices))
    dist, idx = tree.query(vertices, k=count)
    rel = vertices[idx] - vertices[:, None, :]
    local = np.stack([np.sum(rel * frames[:, None, :, j], axis=-1) for j in range(3)], axis=-1)
    agree = np.sum(normals[idx] * normals[:, None, :], axis=-1) > 0.5
    weight = (agree & ((dist <= radius) | (np.arange(count) < 12))).astype(float)
    k1, k2, direction, slope = quadric_curvatures(local, weight)
    normal, d1 = fitted_frame(frames, direction, slope)
    return CurvatureField(k1, k2, d1, normal, float(radius))


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
    n = normal / norm3(normal)
    (t1,), (t2,) = tangents(n[None])
    rel = neighbours - center
    order = np.argsort(np.linalg.norm(rel, axis=1))
    local = times(rel[order], np.stack([t1, t2, n]).T)
    counts = [s for s in sorted(set(min(s, len(local)) for s in sizes)) if s >= 6]
    # a fit needs six independent monomials among its points
    counts = [s for s in counts
              if np.linalg.matrix_rank(np.stack([local[:s, 0] ** 2, local[:s, 0] * local[:s, 1], local[:s, 1] ** 2,
                                                 local[:s, 0], local[:s, 1], np.ones(s)], axis=1)) == 6]
    if not counts:
        return float("nan"), float("nan")
    weight = (np.arange(len(local))[None, :] < np.array(counts)[:, None]).astype(float)
    k1, k2, _, _ = quadric_curvatures(np.broadcast_to(local, (len(counts), *local.shape)), weight)
    arr = np.stack([k1, k2], axis=1)
    return float(np.median(arr[:, 0])), float(np.median(arr[:, 1]))
