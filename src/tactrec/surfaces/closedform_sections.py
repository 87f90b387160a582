"""Plane sections of a closed-form surface, traced in its (u, v) domain (the touches of Section 4.3)."""

from __future__ import annotations

import math

import numpy as np

from ..linalg import cross, dot3

__all__ = ["trace_sections", "unit_vectors", "project_out"]


def unit_vectors(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``a (..., 3)`` scaled to unit length, and their lengths ``(...)``."""
    norm = np.linalg.norm(a, axis=-1, keepdims=True)
    with np.errstate(all="ignore"):
        return a / np.where(norm > 0, norm, 1.0), norm[..., 0]


def project_out(unit: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """``(I - unit unit^T) vec`` along the last axis."""
    return vec - unit * np.sum(unit * vec, axis=-1, keepdims=True)


def trace_sections(surface, site, tangents, *, spacing: float, count: int, substeps: int) -> np.ndarray:
    """:meth:`ClosedFormSurface.plane_sections` (which see) for ``surface``: ``(k, count, 3)``."""
    frame = surface.site_frame(site)
    p, n = frame.point, frame.normal
    tangents = np.asarray(tangents, dtype=np.float64)
    tangents = unit_vectors(project_out(n, tangents))[0]
    planes = unit_vectors(np.cross(n, tangents))[0]                       # (k, 3)
    k = len(tangents)
    targets = (np.arange(count) - (count - 1) / 2.0) * spacing
    smax = float(np.max(np.abs(targets)))
    # half-curves: forward (+tangent) and backward (-tangent)
    m = np.concatenate([planes, planes])
    direction = np.concatenate([tangents, -tangents])
    h = spacing / substeps
    nsteps = int(math.ceil(smax / h)) + 2
    uv = np.repeat(np.asarray(frame.site)[None], 2 * k, axis=0)
    uvs = [uv.copy()]
    arclen = [np.zeros(2 * k)]
    alive = np.ones(2 * k, dtype=bool)
    prev = direction.copy()

    def velocity(uv_, prev_):
        s_, su, sv, *_ = surface._derivatives(uv_[:, 0], uv_[:, 1])
        normal = cross(su, sv)
        nn = surface._orientation(s_, normal)[:, None] * unit_vectors(normal)[0]
        t = unit_vectors(cross(m, nn))[0]
        t = np.where(np.sum(t * prev_, axis=1, keepdims=True) < 0, -t, t)
        a, b, c = dot3(su, su), dot3(su, sv), dot3(sv, sv)           # J^T J for J = [su sv], 2 x 2
        gu, gv = dot3(su, t), dot3(sv, t)
        with np.errstate(all="ignore"):
            det = a * c - b * b
            w = np.stack([(c * gu - b * gv) / det, (a * gv - b * gu) / det], axis=-1)
        return w, t

    for _ in range(nsteps):
        w1, t1 = velocity(uv, prev)
        w2, _ = velocity(uv + 0.5 * h * w1, t1)
        w3, _ = velocity(uv + 0.5 * h * w2, t1)
        w4, _ = velocity(uv + h * w3, t1)
        new = uv + h / 6.0 * (w1 + 2 * w2 + 2 * w3 + w4)
        new = _onto_planes(surface, new, p, m)
        new[:, 0] = surface.domain_u.wrap(new[:, 0]) if surface.domain_u.periodic else new[:, 0]
        new[:, 1] = surface.domain_v.wrap(new[:, 1]) if surface.domain_v.periodic else new[:, 1]
        alive &= surface.inside(new) & np.all(np.isfinite(new), axis=1)
        step3d = np.linalg.norm(surface.evaluate(new[:, 0], new[:, 1]) - surface.evaluate(uv[:, 0], uv[:, 1]), axis=1)
        arclen.append(arclen[-1] + step3d)
        uvs.append(new)
        prev = t1
        uv = new
    if not np.all(alive):
        raise ValueError("a section curve leaves the surface's domain (or meets a singular point)")
    uvs = np.stack(uvs, axis=1)                                      # (2k, steps+1, 2)
    arclen = np.stack(arclen, axis=1)
    out = np.empty((k, count, 3))
    for j in range(k):
        for half, sign in ((j, 1.0), (j + k, -1.0)):
            sel = targets * sign >= 0
            s_abs = np.abs(targets[sel])
            path = _unwrap(surface, uvs[half])
            uv_t = np.stack([np.interp(s_abs, arclen[half], path[:, i]) for i in range(2)], axis=-1)
            uv_t = _onto_planes(surface, uv_t, p, np.repeat(m[half][None], len(uv_t), axis=0))
            out[j, sel] = surface.evaluate(uv_t[:, 0], uv_t[:, 1])
    return out

def _unwrap(surface, path: np.ndarray) -> np.ndarray:
    """A (u, v) path with its periodic parameters unwrapped: ``(n, 2)``."""
    path = path.copy()
    for i, dom in enumerate((surface.domain_u, surface.domain_v)):
        if dom.periodic:
            path[:, i] = np.unwrap(path[:, i], period=dom.length)
    return path

def _onto_planes(surface, uv, p, m, iterations: int = 3):
    """Newton steps moving (u, v) onto the planes ``(sigma - p) . m = 0``."""
    for _ in range(iterations):
        s, su, sv, *_ = surface._derivatives(uv[:, 0], uv[:, 1])
        r = np.sum((s - p) * m, axis=1)
        g = np.stack([np.sum(su * m, axis=1), np.sum(sv * m, axis=1)], axis=1)
        with np.errstate(all="ignore"):
            uv = uv - (r / np.sum(g * g, axis=1))[:, None] * g
    return uv
