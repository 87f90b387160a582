"""A surface offset outward by a radius: the surface a round tip's centres lie on.

:class:`Offset` wraps any surface model: its :meth:`~Offset.planes` and
:meth:`~Offset.distance` measure the signed distance minus the radius, and
everything else (closest points, the name, the triangles) is the wrapped
model's.  A mesh's signed distance is exact; a closed-form surface's
first-order distance ``f / |grad f|`` (eq. 11) is off by about ``r^2 kappa /
2`` at the centres, so its offset measures the distance to the foot point
(:func:`foot_distance`): the offset of the implicit surface.  A mesh offset
for the search (its places, curvatures and distance field lifted too) is
:class:`tactrec.surfaces.mesh_offset.OffsetMesh`, an :class:`Offset`; how a
touch uses either is :mod:`tactrec.tip`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FOOT_STEPS", "foot_distance", "Offset", "offset"]

#: tangent-plane steps of :func:`foot_distance` (each one implicit evaluation; the tangential error
#: shrinks by about ``r |kappa|`` a step)
FOOT_STEPS = 12


def foot_distance(model, points: np.ndarray, steps: int = FOOT_STEPS) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances ``(...)`` of ``points (..., 3)`` to a closed-form surface (positive outside)
    and the unit normals ``(..., 3)`` at their foot points: from each point, ``steps`` projections
    onto the tangent plane at the current foot estimate (``q <- x - ((x - q') . n) n``, ``q' = q -
    (f / |grad f|) n``), whose fixed point ``q`` has ``x - q`` along the normal at ``q``; then one
    Newton step onto ``f = 0``.  Not finite where ``grad f`` vanishes."""
    x = np.asarray(points, dtype=np.float64)
    q = x
    with np.errstate(all="ignore"):
        for _ in range(steps):
            fg = model.implicit(q, order=1)
            norm = np.sqrt(np.sum(fg[..., 1:] * fg[..., 1:], axis=-1))
            n = fg[..., 1:] / norm[..., None]
            on = q - (fg[..., 0] / norm)[..., None] * n
            q = x - np.sum((x - on) * n, axis=-1)[..., None] * n
        fg = model.implicit(q, order=1)
        norm = np.sqrt(np.sum(fg[..., 1:] * fg[..., 1:], axis=-1))
        n = fg[..., 1:] / norm[..., None]
        q = q - (fg[..., 0] / norm)[..., None] * n
        return np.sum((x - q) * n, axis=-1), n


class Offset:
    """A surface model offset outward by ``radius`` (module text): :meth:`planes` and
    :meth:`distance` measure the signed distance minus the radius, against the planes of the
    wrapped model at the closest (foot) points; everything else is the wrapped model's.

    ``radius`` is one number, or one per point ``(m,)`` for calls on ``m`` points at a time
    (``(..., m, 3)``, or ``(h * m, 3)`` flattened point-fastest), as a session's touches of
    different tips are measured together."""

    def __init__(self, model, radius):
        self.model = model
        r = np.asarray(radius, dtype=np.float64)
        self.radius = float(r) if r.ndim == 0 else r

    def __getattr__(self, name):
        if name == "model":                       # not yet set (a copy being made): no recursion
            raise AttributeError(name)
        return getattr(self.model, name)

    def _less(self, d: np.ndarray) -> np.ndarray:
        r = self.radius
        if isinstance(r, float):
            return d - r
        return (d.reshape(-1, len(r)) - r).reshape(d.shape)

    def planes(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances minus the radius ``(...)`` and the planes' unit normals ``(..., 3)``."""
        if self.model.kind == "mesh":
            d, n = self.model.planes(points)
        else:
            d, n = foot_distance(self.model, points)
        return self._less(np.asarray(d, dtype=np.float64)), n

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distances ``(...)`` of ``points (..., 3)`` to the offset surface."""
        return np.abs(self.planes(points)[0])

    def __repr__(self) -> str:
        return f"Offset({self.model!r}, {self.radius!r})"


def offset(model, radius):
    """``model`` itself where every radius is 0, else :class:`Offset` (one radius where all agree)."""
    r = np.asarray(radius, dtype=np.float64)
    if not np.any(r):
        return model
    if r.ndim and np.all(r == r.flat[0]):
        r = r.flat[0]
    return Offset(model, r)
