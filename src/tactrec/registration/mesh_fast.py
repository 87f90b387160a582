"""Fast registration onto a triangle mesh (method ``fast``).

Where the paper (Section 5.3) walks from a few sampled vertices, sectioning
the mesh for every vertex and every 10-degree rotation, this method

1. ranks *every* vertex by how close its fitted curvatures (eq. 14, one
   vectorised fit per vertex: :meth:`MeshModel.curvature_field`) are to the
   estimate, instead of cutting at a hard ``delta``, and keeps the best
   ``candidates`` of them, at most one per cell of a grid one data radius
   across divided by ``spread``;
2. poses the data at each candidate from the two frames alone: the data
   normal onto the vertex normal and the data's first principal direction
   onto the vertex's, either way round (at umbilic points, where the
   direction means nothing, a 30-degree scan instead);
3. scores every pose at once by the exact mean distance of a subset of the
   data points to the mesh (libigl's AABB tree), and
4. refines the best poses in all six degrees of freedom by point-to-plane
   Gauss-Newton (ICP) on all data points, reporting the exact mean distance
   (eq. 12's error, with true distances instead of eq. 15's sections).

``bound`` (the best error found so far on other models) skips refining
poses that cannot beat it.
"""

from __future__ import annotations

import numpy as np

from ..estimation import LocalGeometry
from ..surfaces.mesh import MeshModel, quadric_curvatures
from ..tables import CurvatureTable
from .result import Registration, local_frame

__all__ = ["register", "DEFAULTS", "curvature_field"]

DEFAULTS = {
    "candidates": 600,      # vertices kept after ranking by curvature
    "spread": 4.0,          # at most one candidate per cell of (data radius / spread)
    "coarse_points": 8,     # data points per curve in the coarse score
    "refine": 16,           # poses refined per model
    "iterations": 10,       # Gauss-Newton steps per refined pose, on vertex planes
    "final": 3,             # poses refined again on the exact surface with all points
    "final_iterations": 4,
    "umbilic": 0.004,       # |k1 - k2| below this (1/model units): scan the rotation instead
}


def curvature_field(model: MeshModel):
    """``k1, k2, d1`` of every vertex, computed once per model."""
    field = model.__dict__.get("_curvature_field")
    if field is None:
        model.__dict__["_curvature_radius"] = 3.0 * model.mean_edge
        field = model.curvature_field(radius=model.__dict__["_curvature_radius"])
        model.__dict__["_curvature_field"] = field
    return field


def _rotations(axis_angle: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(n, 3, 3)`` from rotation vectors ``(n, 3)`` (Rodrigues)."""
    theta = np.linalg.norm(axis_angle, axis=1)
    k = axis_angle / np.where(theta > 0, theta, 1.0)[:, None]
    K = np.zeros((len(k), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def _mean_distance(model: MeshModel, R: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Mean distance to the mesh of ``x (m, 3)`` under each pose ``R (h, 3, 3), t (h, 3)``."""
    moved = np.einsum("hij,mj->hmi", R, x) + t[:, None, :]
    return model.distance(moved.reshape(-1, 3)).reshape(len(R), -1).mean(axis=1)


def _vertex_tree(model: MeshModel):
    tree = model.__dict__.get("_vertex_tree")
    if tree is None:
        from scipy.spatial import cKDTree

        tree = model.__dict__["_vertex_tree"] = cKDTree(model.vertices)
    return tree


def _plane_distance(model: MeshModel, moved: np.ndarray):
    """Distance of ``moved (..., 3)`` to the tangent plane of its nearest vertex:
    a cheap stand-in for the distance to the mesh.  Returns it and the vertices."""
    _, v = _vertex_tree(model).query(moved.reshape(-1, 3))
    v = v.reshape(moved.shape[:-1])
    return np.abs(np.sum((moved - model.vertices[v]) * model.vertex_normals[v], axis=-1)), v


def refine(model: MeshModel, R: np.ndarray, t: np.ndarray, x: np.ndarray, *, iterations: int,
           exact: bool = True):
    """Point-to-plane Gauss-Newton on the poses ``R (h, 3, 3), t (h, 3)`` of the data ``x (m, 3)``:
    against the nearest vertex's tangent plane, or (``exact``) the closest point's face.

    Returns the refined poses and their exact mean distances ``(h,)``.
    """
    normals = model.face_normals
    R, t = R.copy(), t.copy()
    for _ in range(iterations):
        moved = np.einsum("hij,mj->hmi", R, x) + t[:, None, :]                     # (h, m, 3)
        if exact:
            _, face, closest = model.closest_points(moved.reshape(-1, 3))
            n = normals[face].reshape(moved.shape)
            closest = closest.reshape(moved.shape)
        else:
            _, v = _plane_distance(model, moved)
            n, closest = model.vertex_normals[v], model.vertices[v]
        r = np.sum((moved - closest) * n, axis=2)                                   # (h, m)
        J = np.concatenate([np.cross(moved, n), n], axis=2)                         # (h, m, 6)
        JtJ = np.einsum("hmi,hmj->hij", J, J)
        # Levenberg-Marquardt damping: a flat or cylindrical patch leaves directions unconstrained
        damp = 1e-6 * (np.trace(JtJ, axis1=1, axis2=2)[:, None, None] / 6.0 + 1e-12)
        step = np.linalg.solve(JtJ + damp * np.eye(6), -np.einsum("hmi,hm->hi", J, r)[..., None])[..., 0]
        dR = _rotations(step[:, :3])
        R = dR @ R
        t = np.einsum("hij,hj->hi", dR, t) + step[:, 3:]
        if np.max(np.abs(step)) < 1e-9:
            break
    if exact:
        return R, t, _mean_distance(model, R, t, x)
    moved = np.einsum("hij,mj->hmi", R, x) + t[:, None, :]
    return R, t, _plane_distance(model, moved)[0].mean(axis=1)


def register(model: MeshModel, table: CurvatureTable, geometry: LocalGeometry, points: np.ndarray, *,
             curves=None, bound: float = np.inf, candidates: int = DEFAULTS["candidates"],
             spread: float = DEFAULTS["spread"], coarse_points: int = DEFAULTS["coarse_points"],
             refine_poses: int = DEFAULTS["refine"], iterations: int = DEFAULTS["iterations"],
             umbilic: float = DEFAULTS["umbilic"], final: int = DEFAULTS["final"],
             final_iterations: int = DEFAULTS["final_iterations"], coarse_exact: bool = False,
             coarse_iterations: int = 0,
             exact_refine: bool = False, **_ignored) -> Registration:
    """Register the data onto ``model``: candidates by curvature rank, poses
    from the principal frames, coarse exact scores, six-DoF refinement."""
    if curves is None:
        raise ValueError("mesh registration needs the data curves")
    k1, k2, d1 = curvature_field(model)
    x = np.asarray(points, dtype=np.float64)
    radius = float(np.max(np.linalg.norm(x - geometry.contact, axis=1)))
    if radius > model.size:
        return Registration.rejection(model.name, "the touch is larger than the model")
    # 1. the data's curvatures at the scale of the mesh's own fits, every vertex ranked by them,
    #    the best of each cell kept
    L0 = local_frame(geometry.normal, geometry.directions[0])
    local = (x - geometry.contact) @ L0.T
    near = np.linalg.norm(local[:, :2], axis=1) <= model.__dict__["_curvature_radius"]
    if near.sum() < 12:
        near = np.argsort(np.linalg.norm(local[:, :2], axis=1))[:12]
    dk1, dk2, (u, v) = quadric_curvatures(local[near][None], np.ones((1, len(local[near]))))
    dk1, dk2 = float(dk1[0]), float(dk2[0])
    direction = u[0] * L0[0] + v[0] * L0[1]
    gap = np.hypot(k1 - dk1, k2 - dk2)
    order = np.argsort(gap, kind="stable")
    cell = np.floor((model.vertices[order] - model.vertices.min(axis=0)) / (radius / spread)).astype(np.int64)
    _, first = np.unique((cell[:, 0] * (cell[:, 1].max() + 1) + cell[:, 1]) * (cell[:, 2].max() + 1) + cell[:, 2],
                         return_index=True)
    chosen = order[np.sort(first)][:candidates]
    # 2. poses from the frames: data (t1, t2, N) onto vertex (d1, n x d1, n), psi about the normal
    L = local_frame(geometry.normal, direction)
    n = model.vertex_normals[chosen]
    F = np.stack([d1[chosen], np.cross(n, d1[chosen]), n], axis=2)                  # (c, 3, 3) columns
    round_ = np.abs(k1[chosen] - k2[chosen]) < umbilic
    if abs(dk1 - dk2) < umbilic:
        round_[:] = True
    psis = [np.array([0.0, np.pi]) if not r else np.deg2rad(np.arange(0.0, 360.0, 30.0)) for r in round_]
    owner = np.repeat(np.arange(len(chosen)), [len(p) for p in psis])
    psi = np.concatenate(psis)
    c, s = np.cos(psi), np.sin(psi)
    Rz = np.zeros((len(psi), 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    R = F[owner] @ Rz @ L
    t = model.vertices[chosen][owner] - np.einsum("hij,j->hi", R, geometry.contact)
    # 3. coarse score on a subset of the points
    subset = np.concatenate([np.asarray(cv, dtype=np.float64)[np.linspace(0, len(cv) - 1, coarse_points).round()
                                                              .astype(int)] for cv in curves])
    if coarse_exact:
        coarse = _mean_distance(model, R, t, subset)
    elif coarse_iterations:
        R, t, coarse = refine(model, R, t, subset, iterations=coarse_iterations, exact=False)
    else:
        moved = np.einsum("hij,mj->hmi", R, subset) + t[:, None, :]
        coarse = _plane_distance(model, moved)[0].mean(axis=1)
    # the best rotation of each candidate, then the best candidates: distinct places, not one place
    # under several rotations
    order = np.lexsort((coarse, owner))
    per_candidate = order[np.r_[True, owner[order][1:] != owner[order][:-1]]]
    keep = per_candidate[np.argsort(coarse[per_candidate])][:refine_poses]
    keep = keep[coarse[keep] < 4.0 * bound + 1e-12] if np.isfinite(bound) else keep
    if len(keep) == 0:
        return Registration.rejection(model.name, f"pruned: coarse error {coarse.min():.3g} cannot beat "
                                                  f"{bound:.3g}")
    # 4. six-DoF refinement: on vertex planes with a few points per curve, then exact on all points
    middle = np.concatenate([np.asarray(cv, dtype=np.float64)[np.linspace(0, len(cv) - 1, 3 * coarse_points)
                                                              .round().astype(int)] for cv in curves])
    R, t, error = refine(model, R[keep], t[keep], middle, iterations=iterations, exact=exact_refine)
    best = np.argsort(error)[:final]
    R, t, error = refine(model, R[best], t[best], x, iterations=final_iterations)
    b = int(np.argmin(error))
    R, t = R[b], t[b]
    _, face, location = model.closest_points((R @ geometry.contact + t)[None])
    return Registration(model=model.name, error=float(error[b]), location=location[0], rotation=R,
                        translation=t, candidates=len(chosen), site=np.array([float(face[0])]), phi=None)
