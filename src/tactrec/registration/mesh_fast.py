"""Fast registration onto a triangle mesh (method ``fast``).

Where the paper (Section 5.3) cuts the lookup at a hard ``delta`` and walks
from the survivors, sectioning the mesh for every vertex and every 10-degree
rotation, this method

1. ranks *every* vertex by how close its principal curvatures (one weighted
   paraboloid fit, eq. 14, per vertex: :meth:`MeshModel.curvature_field`) are
   to the data's, both fitted at the same scale (three mean edges), and keeps
   the best ``candidates``, at most one per cell of a grid a quarter of the
   touch's radius across, so the candidates are distinct places;
2. poses the data at each candidate from the frames alone: the data normal
   onto the vertex normal and the data's first principal direction onto the
   vertex's, either way round; where either point is (nearly) umbilic and the
   direction means nothing, every 30 degrees about the normal instead;
3. improves every pose by a Gauss-Newton step against the tangent plane of
   the nearest vertex (a k-d tree query: the cheap stand-in for the
   distance to the mesh; the exact closest points instead when the touch
   spans fewer than ``exact_below`` mean edges, where vertex planes are too
   coarse), and the ``screen`` poses whose step predicts the best fit by
   further steps; keeps each candidate's best rotation and the best
   ``refine`` candidates;
4. refines those in all six degrees of freedom by point-to-plane
   Gauss-Newton on the exact closest points (libigl's AABB tree), and the
   best ``final`` again on all data points.

The error is eq. 12's mean distance of the data points to the model, with
exact point-to-mesh distances instead of eq. 15's sections.  ``bound`` (the
best error found so far on other models) skips the refinement of a model
whose cheap scores cannot come near it; :func:`promise` orders the models so
that the bound tightens early.  :func:`polish` continues the refinement of a
registration: :func:`tactrec.recognition.recognize` calls it on the best few
models only.  Two wider searches follow when the result is in doubt:
:func:`widen` on the few models that fit about as well as the best when even
the best fits only loosely (a flat or sharp patch, where the curvature ranks
the true place low), after registering again without the bound the models
pruned near the best (:func:`revisit`), and :func:`rescue` on every model when
none fits.
"""

from __future__ import annotations

import numpy as np

from ..estimation import LocalGeometry
from ..surfaces.mesh import MeshModel, quadric_curvatures
from ..tables import CurvatureTable
from .result import (Registration, apply_poses, cross, local_frame, point_to_plane_step, rotations_from_vectors,
                     rotations_z)

__all__ = ["register", "polish", "widen", "widen_scope", "revisit", "rescue", "needs_rescue", "refine", "prepare",
           "promise", "starting_poses", "DEFAULTS", "curvature_field"]

DEFAULTS = {
    "candidates": 150,      # distinct places kept after ranking every vertex by curvature
    "spread": 4.0,          # at most one candidate per cell of (touch radius / spread)
    "coarse_points": 5,     # data points per curve in the cheap stages
    "coarse_iterations": 2,  # Gauss-Newton steps on vertex planes
    "screen": 40,           # poses kept for the second cheap step, by the first step's predicted fit
    "refine": 16,           # candidates refined on the exact surface
    "iterations": 6,        # exact Gauss-Newton steps for the refined candidates, on 3 x coarse_points a curve
    "final": 1,             # poses refined again with all data points
    "final_iterations": 2,  # (the best few models get :func:`polish`'s ten more)
    "umbilic": 0.05,        # |k1 - k2| x touch radius below this: scan the rotation instead
    "prune": 2.0,           # skip a model whose best cheap score exceeds prune x bound
    "hard": 0.01,           # rescue: search every model again when the best error exceeds this x touch radius
    "loose": 0.001,         # widen: the best error exceeds this x touch radius ...
    "noise_fit": 2.0,       # ... and this x the data's noise (a true fit's mean distance is ~0.8 sigma) ...
    "rival": 2.0,           # ... and the runner-up's is within this factor of it
    "reach": 3.0,           # widen on the models whose error is within this factor of the best ...
    "rivals": 12,           # ... at most this many, best first
    "wide_candidates": 600,  # candidates of the widened search
    "revisit": 4.0,         # before widening, search again unbounded the models pruned within this x the best error
    "exact_below": 4.0,     # a touch under this many mean edges in radius: exact distances from the start
    "tolerance": 1e-5,      # Gauss-Newton stops when no point moves more than this x the touch's reach
}


def curvature_field(model: MeshModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``k1, k2 (V,), d1 (V, 3)`` of every vertex and the fit radius (:attr:`MeshModel.fine_curvatures`)."""
    return model.fine_curvatures


def prepare(model: MeshModel) -> None:
    """Build what registration needs once per model (curvature field, k-d tree, AABB tree)."""
    curvature_field(model)
    model.vertex_tree
    model.distance(model.vertices[:1])


def _mean_distance(model: MeshModel, R: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Exact mean distance to the mesh of ``x (m, 3)`` under each pose ``R (h, 3, 3), t (h, 3)``."""
    return model.distance(apply_poses(R, t, x).reshape(-1, 3)).reshape(len(R), -1).mean(axis=1)


def _nearest_planes(model: MeshModel, moved: np.ndarray):
    """The nearest vertex's position and normal for every point of ``moved (..., 3)``."""
    _, v = model.vertex_tree.query(moved.reshape(-1, 3))
    v = v.reshape(moved.shape[:-1])
    return model.vertices[v], model.vertex_normals[v]


def refine(model: MeshModel, R: np.ndarray, t: np.ndarray, x: np.ndarray, *, iterations: int,
           exact: bool = True, predict: bool = False,
           tolerance: float = DEFAULTS["tolerance"]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point-to-plane Gauss-Newton (damped) on poses ``R (h, 3, 3), t (h, 3)`` of data ``x (m, 3)``.

    Each step linearises ``r_i = (R x_i + t - c_i) . n_i`` about the current
    pose, with ``c_i, n_i`` the closest point on the mesh and its face normal
    (``exact``) or the nearest vertex and its normal.  The steps stop early
    once no data point moves by more than ``tolerance`` x the data's reach
    (its largest distance from its centroid).  Returns the poses and their
    mean distances ``(h,)`` (exact or to those planes); with ``predict``, the
    distances the last step's linearisation predicts, which spares a last
    query of every point.
    """
    R, t = R.copy(), t.copy()
    predicted = np.zeros((len(R), len(x))) if predict else None
    reach = float(np.max(np.linalg.norm(x - x.mean(axis=0), axis=1)))
    active = np.arange(len(R))                      # the poses still moving
    for _ in range(iterations):
        moved = apply_poses(R[active], t[active], x)                                      # (a, m, 3)
        if exact:
            _, face, closest = model.closest_points(moved.reshape(-1, 3))
            n, closest = model.face_normals[face].reshape(moved.shape), closest.reshape(moved.shape)
        else:
            closest, n = _nearest_planes(model, moved)
        residual = np.sum((moved - closest) * n, axis=2)
        if predict:
            R[active], t[active], step, predicted[active] = point_to_plane_step(R[active], t[active], moved, n,
                                                                                residual, predict=True)
        else:
            R[active], t[active], step = point_to_plane_step(R[active], t[active], moved, n, residual)
        # how far the step moved the data: at most |w x c + v| + |w| reach, c the moved centroid
        w, v = step[:, :3], step[:, 3:]
        moves = np.linalg.norm(cross(w, moved.mean(axis=1)) + v, axis=1) + np.linalg.norm(w, axis=1) * reach
        active = active[moves > tolerance * reach]
        if len(active) == 0:
            break
    if predicted is not None:
        return R, t, np.abs(predicted).mean(axis=1)
    if exact:
        return R, t, _mean_distance(model, R, t, x)
    moved = apply_poses(R, t, x)
    closest, n = _nearest_planes(model, moved)
    return R, t, np.abs(np.sum((moved - closest) * n, axis=2)).mean(axis=1)


def _touch_radius(geometry: LocalGeometry, x: np.ndarray) -> float:
    """The touch's radius: the largest distance of a data point ``x (m, 3)`` from the contact."""
    return float(np.max(np.linalg.norm(x - geometry.contact, axis=1)))


def _subset(curves, per_curve: int) -> np.ndarray:
    return np.concatenate([np.asarray(c, dtype=np.float64)[np.linspace(0, len(c) - 1, per_curve).round().astype(int)]
                           for c in curves])


def _data_curvatures(model: MeshModel, geometry: LocalGeometry, x: np.ndarray, radius: float):
    """The data's principal curvatures and first direction, fitted like the model's (within ``radius``)."""
    L0 = local_frame(geometry.normal, geometry.directions[0])
    local = (x - geometry.contact) @ L0.T
    r = np.linalg.norm(local[:, :2], axis=1)
    near = r <= radius
    if near.sum() < 12:
        near = np.argsort(r)[:12]
    k1, k2, (u, v) = quadric_curvatures(local[near][None], np.ones((1, len(local[near]))))
    return float(k1[0]), float(k2[0]), u[0] * L0[0] + v[0] * L0[1]


def _result(model: MeshModel, geometry: LocalGeometry, R, t, error, candidates: int) -> Registration:
    _, face, location = model.closest_points((R @ geometry.contact + t)[None])
    return Registration(model=model.name, error=float(error), location=location[0], rotation=R, translation=t,
                        candidates=candidates, site=np.array([float(face[0])]), phi=None)


#: candidates posed and scored at once (bounds the memory of an exhaustive search)
CHUNK = 1000


def _frame_poses(model, geometry, chosen, k1, k2, d1, direction, *, umbilic, dk, tilt):
    """Step 2 for the candidate vertices ``chosen (c,)``: poses ``R (h, 3, 3), t (h, 3)`` and the
    candidate each belongs to, ``owner (h,)``."""
    n = model.vertex_normals[chosen]
    F = np.stack([d1[chosen], cross(n, d1[chosen]), n], axis=2)                     # (c, 3, 3) columns
    scan = (np.abs(k1[chosen] - k2[chosen]) < umbilic) | (abs(dk[0] - dk[1]) < umbilic)
    counts = np.where(scan, 12, 2)                        # every 30 degrees, or the frame either way round
    owner = np.repeat(np.arange(len(chosen)), counts)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(counts) - counts, counts)
    R = F[owner] @ rotations_z(k * np.where(scan[owner], np.pi / 6, np.pi))
    if tilt > 0:
        a = np.deg2rad(tilt)
        T = rotations_from_vectors(np.array([[0, 0, 0], [a, 0, 0], [-a, 0, 0], [0, a, 0], [0, -a, 0]], dtype=float))
        R = (R[:, None] @ T[None]).reshape(-1, 3, 3)
        owner = np.repeat(owner, len(T))
    R = R @ local_frame(geometry.normal, direction)
    t = model.vertices[chosen][owner] - np.einsum("hij,j->hi", R, geometry.contact)
    return R, t, owner


def _cheap_poses(model, geometry, curves, chosen, k1, k2, d1, direction, radius, *, umbilic, dk, tilt,
                 coarse_points, coarse_iterations, exact, screen):
    """Steps 2-3 for the candidate vertices ``chosen (c,)``: each one's best pose ``R (c, 3, 3), t (c, 3)``
    after the cheap Gauss-Newton steps, and its cheap score ``(c,)``.

    With ``screen``, only the ``screen`` poses whose first step predicts the best fit take the
    further steps; the others are dropped."""
    R, t, owner = _frame_poses(model, geometry, chosen, k1, k2, d1, direction, umbilic=umbilic, dk=dk, tilt=tilt)
    x = _subset(curves, coarse_points)
    if screen and len(R) > screen and coarse_iterations > 1:
        R, t, first = refine(model, R, t, x, iterations=1, exact=exact, predict=True)
        keep = np.argsort(first, kind="stable")[:screen]
        owner = owner[keep]
        R, t, cheap = refine(model, R[keep], t[keep], x, iterations=coarse_iterations - 1, exact=exact)
    else:
        # scored by the last step's predicted residual, as the screen does: a last exact query of
        # every pose would cost a third of the stage (the refinement re-scores the kept ones)
        R, t, cheap = refine(model, R, t, x, iterations=coarse_iterations, exact=exact, predict=exact)
    order = np.lexsort((cheap, owner))
    best = order[np.r_[True, owner[order][1:] != owner[order][:-1]]]             # one per candidate, in order
    return R[best], t[best], cheap[best]


def _candidates(model: MeshModel, geometry: LocalGeometry, x: np.ndarray, radius: float, *, spread: float,
                count: int | None):
    """Step 1: vertices ranked by curvature gap, the best of each grid cell (all of them if ``count`` is None).

    Returns the chosen vertices, the data's curvatures ``(k1, k2)`` and first principal direction."""
    k1, k2, _, fit_radius = curvature_field(model)
    dk1, dk2, direction = _data_curvatures(model, geometry, x, fit_radius)
    gap = np.hypot(k1 - dk1, k2 - dk2)
    if count is None:
        return np.argsort(gap, kind="stable"), (dk1, dk2), direction
    (low, high), size = model.bounds, radius / spread
    span = np.floor((high - low) / size).astype(np.int64) + 1
    for head in (20 * count, len(gap)):      # the best-ranked vertices usually hold enough distinct cells
        order = np.argpartition(gap, head)[:head] if head < len(gap) else np.arange(len(gap))
        order = order[np.lexsort((order, gap[order]))]
        cell = np.floor((model.vertices[order] - low) / size).astype(np.int64)
        _, first = np.unique((cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2], return_index=True)
        if len(first) >= count:
            break
    return order[np.sort(first)][:count], (dk1, dk2), direction


def promise(model: MeshModel, geometry: LocalGeometry, points: np.ndarray) -> float:
    """How well the model's curvatures can match the data's: the smallest curvature gap over its
    vertices times the touch's radius (lower is more promising).  Models are registered in this
    order, so the bound that prunes later models tightens early."""
    k1, k2, _, fit_radius = curvature_field(model)
    x = np.asarray(points, dtype=np.float64)
    radius = _touch_radius(geometry, x)
    dk1, dk2, _ = _data_curvatures(model, geometry, x, fit_radius)
    return float(np.min(np.hypot(k1 - dk1, k2 - dk2)) * radius)


def starting_poses(model: MeshModel, geometry: LocalGeometry, points: np.ndarray, *,
                   count: int = DEFAULTS["candidates"], spread: float = DEFAULTS["spread"],
                   umbilic: float = DEFAULTS["umbilic"]) -> tuple[np.ndarray, np.ndarray]:
    """The poses ``R (h, 3, 3), t (h, 3)`` the search starts from at the best ``count`` candidates
    (steps 1-2), for other refinements to start from the same places."""
    x = np.asarray(points, dtype=np.float64)
    radius = _touch_radius(geometry, x)
    k1, k2, d1, _ = curvature_field(model)
    chosen, dk, direction = _candidates(model, geometry, x, radius, spread=spread, count=count)
    R, t, _ = _frame_poses(model, geometry, chosen, k1, k2, d1, direction, umbilic=umbilic / radius, dk=dk,
                           tilt=0.0)
    return R, t


def register(model: MeshModel, table: CurvatureTable, geometry: LocalGeometry, points: np.ndarray, *,
             curves=None, bound: float = np.inf, candidates: int = DEFAULTS["candidates"],
             spread: float = DEFAULTS["spread"], coarse_points: int = DEFAULTS["coarse_points"],
             coarse_iterations: int = DEFAULTS["coarse_iterations"], refine_poses: int = DEFAULTS["refine"],
             iterations: int = DEFAULTS["iterations"], final: int = DEFAULTS["final"],
             final_iterations: int = DEFAULTS["final_iterations"], umbilic: float = DEFAULTS["umbilic"],
             prune: float = DEFAULTS["prune"], exact_below: float = DEFAULTS["exact_below"], tilt: float = 0.0,
             screen: int = DEFAULTS["screen"], tolerance: float = DEFAULTS["tolerance"],
             exhaustive: bool = False, **_ignored) -> Registration:
    """Register the data curves onto ``model`` (steps 1-4 of the module text).

    ``points (m, 3)`` are all data points and ``curves`` the same points curve
    by curve, in model units; ``geometry`` the estimate (``table`` is not
    used: the candidates come from the curvature of every vertex).
    ``exhaustive`` starts from every vertex under every 30-degree rotation
    (no ranking, no pruning): the reference the ranking is measured against.
    """
    if curves is None:
        raise ValueError("mesh registration needs the data curves")
    k1, k2, d1, _ = curvature_field(model)
    x = np.asarray(points, dtype=np.float64)
    radius = _touch_radius(geometry, x)
    if radius > model.size:
        return Registration.rejection(model.name, "the touch is larger than the model")
    # 1. every vertex ranked by its curvature gap to the data, the best of each grid cell kept
    chosen, (dk1, dk2), direction = _candidates(model, geometry, x, radius, spread=spread,
                                                count=None if exhaustive else candidates)
    # 2.-3. poses from the frames, a few cheap Gauss-Newton steps for each; each candidate's best rotation
    poses = [_cheap_poses(model, geometry, curves, chosen[i:i + CHUNK], k1, k2, d1, direction, radius,
                          umbilic=np.inf if exhaustive else umbilic / radius, dk=(dk1, dk2), tilt=tilt,
                          coarse_points=coarse_points, coarse_iterations=coarse_iterations,
                          exact=radius < exact_below * model.mean_edge, screen=0 if exhaustive else screen)
             for i in range(0, len(chosen), CHUNK)]
    R = np.concatenate([p[0] for p in poses])
    t = np.concatenate([p[1] for p in poses])
    cheap = np.concatenate([p[2] for p in poses])
    keep = np.argsort(cheap)[:refine_poses]
    if np.isfinite(bound) and not exhaustive:
        keep = keep[cheap[keep] <= prune * bound]
        if len(keep) == 0:
            return Registration.rejection(model.name, f"pruned: no pose came near the best error {bound:.3g}",
                                          cheap=float(cheap.min()))
    # 4. six degrees of freedom on the exact surface, then all points for the best few
    R, t, error = refine(model, R[keep], t[keep], _subset(curves, 3 * coarse_points), iterations=iterations,
                         tolerance=tolerance)
    best = np.argsort(error)[:final]
    R, t, error = refine(model, R[best], t[best], x, iterations=final_iterations, tolerance=tolerance)
    b = int(np.argmin(error))
    return _result(model, geometry, R[b], t[b], error[b], len(chosen))


def polish(model: MeshModel, registration: Registration, geometry: LocalGeometry, points: np.ndarray, *,
           iterations: int = 10, tolerance: float = DEFAULTS["tolerance"], **_ignored) -> Registration:
    """Refine ``registration`` further on all points (``iterations`` exact Gauss-Newton steps)."""
    x = np.asarray(points, dtype=np.float64)
    R, t, error = refine(model, registration.rotation[None], registration.translation[None], x,
                         iterations=iterations, tolerance=tolerance)
    if error[0] < registration.error:
        return _result(model, geometry, R[0], t[0], error[0], registration.candidates)
    return registration


def widen_scope(errors: np.ndarray, geometry: LocalGeometry, points: np.ndarray, *, noise: float = 0.0,
                loose: float = DEFAULTS["loose"], noise_fit: float = DEFAULTS["noise_fit"],
                rival: float = DEFAULTS["rival"], reach: float = DEFAULTS["reach"],
                rivals: int = DEFAULTS["rivals"], hard: float = DEFAULTS["hard"]) -> int:
    """How many of the best-ranked models :func:`widen` should search again (0: none).

    ``errors (k,)`` are the ranked models' errors, ascending, and ``noise`` the
    data's noise sigma, in the units of ``points``.  The search is widened when
    the best fits loosely (its error exceeds ``loose`` x the touch's radius and
    ``noise_fit`` x the noise) and the runner-up fits within ``rival`` x of it:
    the ranking is then a contest between poses that are probably both
    wrong.  It covers the models within ``reach`` x the best error, at most
    ``rivals`` of them.  A touch that nothing fits (the best error exceeds
    ``hard`` x the radius) is widened too, on every model within reach: it
    takes :func:`rescue` on every model after this anyway, so the cap that
    keeps a loose fit quick would save little there, and the rescue's tilted
    search on 150 candidates can miss a small, sharp model's true place that
    600 candidates find."""
    e = np.asarray(errors, dtype=np.float64)
    if len(e) < 2:
        return 0
    radius = _touch_radius(geometry, np.asarray(points, dtype=np.float64))
    if not (max(loose * radius, noise_fit * noise) < e[0] and e[1] <= rival * e[0]):
        return 0
    within = int(np.sum(e <= reach * e[0]))
    return within if needs_rescue(e[0], geometry, points, hard=hard) else int(min(rivals, within))


def revisit(cheap: float, best: float, *, factor: float = DEFAULTS["revisit"]) -> bool:
    """Whether a model the first search pruned with the cheap score ``cheap`` should be searched
    again, without the bound, before the search is widened around the best error ``best``
    (the same units for both).

    The widened search covers the models whose error is within ``reach`` (3) x the best;
    the first search pruned on its cheap scores at ``prune`` (2) x the best error so far.
    The refinement after the cheap stage can bring a pose's score down to half or less
    (a coarse scan, a pose near an edge), so a pruned model whose cheap score lies within
    ``factor`` x the best may well come within that reach once refined."""
    return bool(cheap <= factor * best)


def widen(model: MeshModel, table: CurvatureTable, geometry: LocalGeometry, points: np.ndarray, *,
          curves=None, bound: float = np.inf, candidates: int = DEFAULTS["wide_candidates"],
          **_ignored) -> Registration:
    """The search widened for a loose fit: four times the candidates, every 30 degrees about the
    normal at each, exact distances from the first step, no screening and no pruning by ``bound``.

    On a flat or sharp patch the data's curvature says little, so many places rank
    alike and the true one may rank low; its principal direction means nothing.
    There, too, vertex planes mislead: near a rim or a thin wall the nearest vertex
    can lie across the edge or on the other side, and a step towards its plane
    leads away from the true pose."""
    return register(model, table, geometry, points, curves=curves, candidates=candidates, umbilic=np.inf,
                    screen=0, exact_below=np.inf)


def needs_rescue(bound: float, geometry: LocalGeometry, points: np.ndarray, *, hard: float = DEFAULTS["hard"]) -> bool:
    """Whether no model fits: the best error ``bound`` exceeds ``hard`` x the touch's radius (any units,
    the same for all three)."""
    return bool(bound > hard * _touch_radius(geometry, np.asarray(points, dtype=np.float64)))


def rescue(model: MeshModel, table: CurvatureTable, geometry: LocalGeometry, points: np.ndarray, *,
           curves=None, bound: float = np.inf, hard: float = DEFAULTS["hard"], **_ignored) -> Registration:
    """The wider search, for a touch that no model fits (best error ``bound``, model units).

    If ``bound`` exceeds ``hard`` x the touch's radius (a touch across a
    crease, where the estimated normal can be tens of degrees off), search
    again: every 30 degrees about the normal at every candidate, the normal
    tilted 15 degrees four ways, eight points a curve and twice the cheap
    steps (on the smoother vertex planes), no screening, and twice the poses
    refined.  Otherwise a rejection ("fits already") at no cost."""
    x = np.asarray(points, dtype=np.float64)
    if not needs_rescue(bound, geometry, x, hard=hard):
        return Registration.rejection(model.name, "fits already: no wider search")
    return register(model, table, geometry, x, curves=curves, umbilic=np.inf, tilt=15.0, exact_below=0.0,
                    coarse_points=8, coarse_iterations=2 * DEFAULTS["coarse_iterations"],
                    refine_poses=2 * DEFAULTS["refine"], screen=0)
