"""Where the leading hypotheses disagree: the places a next touch is tried at (:mod:`tactrec.proposal`,
Candidates).

Each hypothesis' surface is drawn at random over the whole object (:data:`SITES` places per
model: random vertices of a mesh), carried into the world by its pose.  A place qualifies when
it can be reached: within ``radius`` of an earlier contact where a reach is given, and on the
side the earlier touches came from: its outward normal within 90 degrees of the mean of theirs
where they all came from one direction, the half-space widening as the mean shortens (touches
from several sides).  At each, the *disagreement* is how
far the nearest rival's surface lies from it, in standard errors of the difference: the rivals'
signed distances ``d`` there over ``sqrt(sigma^2 + s_h^2 + s_g^2)``, where ``sigma`` is the
touches' noise and ``s_h``, ``s_g`` how far the two poses' surfaces there may move under the
touches so far: ``s^2 = sigma^2 j^T (H0 + lambda I)^-1 j`` with ``j`` the distance's pose Jacobian
at the place and ``H0 = J0^T J0`` the earlier touches' (:func:`~tactrec.proposal.gain.information`),
the predicted spread of a point-to-plane fit, and a prior that holds the pose within the object's
size (:func:`pose_spread`).  A place far from the touches, where a small turn of the
pose moves the surface by millimetres, disagrees only by what the poses cannot absorb; a place
beside them, where every pose puts the surface where the touches were, not at all.  The places of
largest disagreement are the candidates; a hypothesis with no rival (a model against
``unknown``) takes the first it draws.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..linalg import dot3, norm3, solve_spd, times
from .gain import model_points, pose_jacobian
from .predict import to_model, to_world

__all__ = ["SITES", "TILT", "Place", "places", "pose_spread", "touched_side"]

#: places drawn at random over each hypothesis' surface (random vertices of a mesh) before the reach
#: and the disagreement pick
SITES = 2000
#: how far past a right angle to the touches' side a face still counts as on it (radians): the tilt
#: of a pose fitted to noisy touches
TILT = 1e-3


@dataclasses.dataclass(frozen=True)
class Place:
    """A candidate place: its site on the hypothesis' model, world point ``(3,)`` and outward unit
    normal ``(3,)``, and the disagreement there (standard errors; ``inf`` without rivals)."""

    site: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    disagreement: float


def pose_spread(model, pose, scale: float, H0: np.ndarray, x_world: np.ndarray, sigma: float) -> np.ndarray:
    """How far ``(n,)`` (world units, one standard error) the surface of ``model`` under ``pose (3, 4)``
    may move along its normal at world points ``x_world (n, 3)`` under a pose fitted to touches of
    information ``H0`` (model units, :func:`~tactrec.proposal.gain.information`) and noise ``sigma``:
    ``sigma sqrt(j^T (H0 + P)^-1 j)``.  The prior ``P`` holds the pose within the object's size:
    ``(sigma s / size)^2`` on a turn measured in model sizes, ``(sigma s)^2`` on a shift (``s`` the
    scale, ``size`` the model's), so that directions the touches leave free (along a cylinder's
    axis, over a flat face) move the surface by about that much."""
    _, J = pose_jacobian(model, model_points(pose, scale, x_world))
    prior = max((float(sigma) * float(scale) / float(model.size)) ** 2, 1e-300)
    P = np.diag([prior * model.size ** 2] * 3 + [prior] * 3)
    C = solve_spd((H0 + P)[None].repeat(6, axis=0), np.eye(6))                   # rows: the inverse, no LAPACK
    return float(sigma) * np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", J, C, J), 0.0))


def places(models: dict, h, pose, H0, rivals: list, contacts: np.ndarray, side: np.ndarray, *, radius: float | None,
           sigma: float, rng) -> list[Place]:
    """The places on hypothesis ``h``'s surface at its ``pose (3, 4)`` (information ``H0``) that can be
    reached, most disagreeing first (module text).  ``rivals``: ``(hypothesis, pose (3, 4), H0)`` of
    the other models' poses; ``contacts (N, 3)`` the earlier contacts and ``side (3,)`` the mean of
    their outward unit normals, world frame; ``radius`` the reach (None: the whole object)."""
    model = models[h.model]
    sites = model.random_sites(SITES, rng=rng)
    x_model, normals = model.site_points(sites)
    if not len(x_model):
        return []
    normals = times(normals, pose[:, :3])                                                # model -> world directions
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    x = to_world(h, x_model)
    # the half-space the touches came from, wider as they come from more sides (the mean of their
    # normals shorter): at its edge a face at right angles is on the side up to the poses' tilt
    ok = dot3(normals, side) >= -(1.0 - min(float(norm3(side)), 1.0)) - TILT
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
            gap = np.abs(np.nan_to_num(d, nan=0.0)) / np.sqrt(sigma ** 2 + own ** 2 + spread ** 2)
            z = np.minimum(z, np.nan_to_num(gap, nan=0.0))
        order = np.lexsort((own, -z))                      # most disagreeing; then the surest place
    else:                                                 # a model against unknown: the places as drawn
        z, order = np.full(len(index), np.inf), np.arange(len(index))
    return [Place(sites[index[i]], x[i], normals[index[i]], float(z[i])) for i in order]


def touched_side(model, h, contacts: np.ndarray) -> np.ndarray:
    """The side the earlier touches came from: the mean of their outward unit normals under ``h``,
    world frame (unit for touches from one direction, shorter as they come from more)."""
    _, n = model.planes(to_model(h, contacts))
    n = times(n, h.rotation)
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return np.nan_to_num(n).mean(axis=0)
