"""Where the leading hypotheses disagree: the places a next touch is tried at (:mod:`tactrec.proposal`,
Candidates).

Each hypothesis' surface is drawn at random over the whole object (:data:`SITES` places per
model), carried into the world by its pose.  A place qualifies when it can be reached: within
``radius`` of an earlier contact where a reach is given, and on the side the earlier touches came
from (its outward normal within 90 degrees of theirs, summed).  At each, the *disagreement* is how
far the nearest rival's surface lies from it, in standard errors of the difference: the rivals'
signed distances ``d`` there over ``sqrt(sigma^2 + s_h^2 + s_g^2)``, where ``sigma`` is the
touches' noise and ``s_h``, ``s_g`` how far the two poses' surfaces there may move under the
touches so far: ``s^2 = sigma^2 j^T H0^-1 j`` with ``j`` the distance's pose Jacobian at the place
and ``H0 = J0^T J0`` the earlier touches' (:func:`~tactrec.proposal.gain.information`), the
predicted spread of a point-to-plane fit.  A place far from the touches, where a small turn of the
pose moves the surface by millimetres, disagrees only by what the poses cannot absorb; a place
beside them, where every pose puts the surface where the touches were, not at all.  The places of
largest disagreement are the candidates; a hypothesis with no rival (a model against
``unknown``) takes the first it draws.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .gain import pose_jacobian
from .predict import to_model, to_world

__all__ = ["SITES", "Place", "places", "pose_spread", "touched_side"]

#: places drawn at random over each hypothesis' surface before the reach and the disagreement pick
SITES = 2000


@dataclasses.dataclass(frozen=True)
class Place:
    """A candidate place: its surface frame on the hypothesis' model, world point ``(3,)`` and outward
    unit normal ``(3,)``, and the disagreement there (standard errors; ``inf`` without rivals)."""

    frame: object
    point: np.ndarray
    normal: np.ndarray
    disagreement: float


def pose_spread(model, pose, scale: float, H0: np.ndarray, x_world: np.ndarray, sigma: float) -> np.ndarray:
    """How far ``(n,)`` (world units, one standard error) the surface of ``model`` under ``pose (3, 4)``
    may move along its normal at world points ``x_world (n, 3)`` under a pose fitted to touches of
    information ``H0`` (model units, :func:`~tactrec.proposal.gain.information`) and noise ``sigma``:
    ``sigma sqrt(j^T H0^-1 j)``.  Directions the touches leave free (a cylinder's axis) are held by a
    ridge of ``1e-9`` of the trace, which leaves them as far as the object's size allows."""
    _, J = pose_jacobian(model, scale * np.asarray(x_world, dtype=np.float64) @ pose[:, :3].T + pose[:, 3])
    H = H0 + 1e-9 * max(float(np.trace(H0)), 1e-300) * np.eye(6)
    C = np.linalg.inv(H)
    return float(sigma) * np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", J, C, J), 0.0))


def places(models: dict, h, pose, H0, rivals: list, contacts: np.ndarray, side: np.ndarray, *, radius: float | None,
           sigma: float, count: int, rng) -> list[Place]:
    """Up to ``count`` places on hypothesis ``h``'s surface at its ``pose (3, 4)`` (information ``H0``),
    most disagreeing first (module text).  ``rivals``: ``(hypothesis, pose (3, 4), H0)`` of the
    other models' poses; ``contacts (N, 3)`` the earlier contacts and ``side (3,)`` their summed
    outward normal, world frame; ``radius`` the reach (None: the whole object)."""
    model = models[h.model]
    frames = [model.site_frame(s) for s in model.random_sites(SITES, rng=rng)]
    if not frames:
        return []
    x_model = np.array([f.point for f in frames])
    normals = np.array([f.normal for f in frames]) @ pose[:, :3]                      # model -> world directions
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    x = to_world(h, x_model)
    ok = normals @ side >= 0.0
    if radius is not None:
        ok &= np.min(np.linalg.norm(x[:, None, :] - contacts[None, :, :], axis=2), axis=1) <= radius
    index = np.nonzero(ok)[0]
    if not len(index):
        return []
    x = x[index]
    own = pose_spread(model, pose, h.scale, H0, x, sigma)
    if rivals:
        z = np.full(len(index), np.inf)
        for g, g_pose, g_H0 in rivals:
            rival = models[g.model]
            d = np.asarray(rival.planes(to_model(g, x))[0], dtype=np.float64) / g.scale
            spread = pose_spread(rival, g_pose, g.scale, g_H0, x, sigma)
            z = np.minimum(z, np.abs(np.nan_to_num(d, nan=0.0)) / np.sqrt(sigma ** 2 + own ** 2 + spread ** 2))
        order = np.lexsort((own, -z))[:count]              # most disagreeing; then the surest place
    else:                                                 # a model against unknown: the places as drawn
        z, order = np.full(len(index), np.inf), np.arange(min(count, len(index)))
    return [Place(frames[index[i]], x[i], normals[index[i]], float(z[i])) for i in order]


def touched_side(model, h, contacts: np.ndarray) -> np.ndarray:
    """The side the earlier touches came from: their outward normals under ``h``, summed, world frame."""
    _, n = model.planes(to_model(h, contacts))
    n = np.asarray(n, dtype=np.float64) @ h.rotation
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return np.nan_to_num(n).sum(axis=0)
