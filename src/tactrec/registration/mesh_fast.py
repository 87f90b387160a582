"""The steps of method ``fast`` on a triangle mesh (after paper Section 5.3).

Where the paper cuts its lookup at a hard ``delta`` and walks from the
survivors, sectioning the mesh for every vertex and 10-degree rotation,
``fast`` searches over hypotheses (place, rotation, tilt of the normal) with
these steps, which :mod:`tactrec.methods.fast` schedules:

1. :func:`places` -- every vertex ranked by how close its principal
   curvatures (one weighted paraboloid fit, eq. 14, per vertex, stored in the
   database) are to the data's, both fitted at the same scale; the best of
   each grid cell (a quarter of the touch's radius across), so that the
   places are distinct;
2. :func:`frame_poses` -- the data posed at a place from the frames alone:
   the data normal onto the vertex normal, then either the data's first
   principal direction onto the vertex's, either way round (``"frames"``),
   or every 30 degrees about the normal from well-defined tangents
   (``"all"``), optionally with the normal tilted four ways;
3. refinement -- damped point-to-plane Gauss-Newton in six degrees of
   freedom on the exact closest points (libigl's AABB tree): the one solver,
   :func:`tactrec.registration.solver.solve`.

The error is eq. 12's mean distance of the data points to the model, with
exact point-to-mesh distances in place of eq. 15's sections.
"""

from __future__ import annotations

import numpy as np

from ..estimation import LocalGeometry
from ..linalg import compose, cross, rotate, stable_order, stable_prefix, times, transform
from ..surfaces.mesh import MeshModel
from ..surfaces.mesh_curvature import fitted_frame, quadric_curvatures, tangents
from ..surfaces.mesh_grid import cells as _cells, first_per_cell
from .result import Registration, local_frame, rotations_from_vectors, rotations_z
from .step import covariance

__all__ = ["places", "curvature_gaps", "leading_places", "first_per_cell", "first_per_place", "first_per_direction",
           "fibonacci_sphere", "frame_poses", "registration", "data_curvatures", "prepare", "starting_poses"]


def prepare(model: MeshModel) -> None:
    """Build what the search needs once per model (curvature field, distance field, AABB tree)."""
    model.fine_curvatures
    model.distance_field
    model.vertex_normals
    model.distance(model.vertices[:1])


def data_curvatures(geometry: LocalGeometry, x: np.ndarray, radius: float):
    """The data's paraboloid fit, made like the model's field (:func:`~tactrec.surfaces.mesh_curvature.curvature_field`):
    one weighted fit to the data points within ``radius`` of the contact (at least 12).

    Returns ``(k1, k2)``, the first principal direction ``(3,)`` and the fitted normal ``(3,)``
    (data frame): the fitted tangent plane, which a faceted or noisy touch gives more steadily
    than the curves' tangents at the contact."""
    L0 = local_frame(geometry.normal, geometry.tangents[0])
    local = times(x - geometry.contact, L0.T)
    r = np.linalg.norm(local[:, :2], axis=1)
    near = r <= radius
    if near.sum() < 12:
        near = stable_order(r)[:12]
    k1, k2, direction, slope = quadric_curvatures(local[near][None], np.ones((1, len(local[near]))))
    normal, d1 = fitted_frame(L0.T[None], direction, slope)
    return (float(k1[0]), float(k2[0])), d1[0], normal[0]


def curvature_gaps(model: MeshModel, geometry: LocalGeometry, x: np.ndarray):
    """Each vertex's curvature gap to the data ``(n,)``: the distance between its principal
    curvatures (one weighted paraboloid fit, eq. 14, per vertex) and the data's, fitted at the same
    scale; and the data's fit (:func:`data_curvatures`)."""
    field = model.fine_curvatures
    dk, direction, normal = data_curvatures(geometry, x, field.radius)
    return np.hypot(field.k1 - dk[0], field.k2 - dk[1]), (dk, direction, normal)


def places(model: MeshModel, geometry: LocalGeometry, x: np.ndarray, radius: float, *, spread: float):
    """Step 1: the distinct places of ``model`` in order of curvature gap to the data.

    Returns the vertices ``(p,)`` (the best of each grid cell ``radius / spread`` across, best
    cell first), their gaps ``(p,)`` and the data's fit (:func:`data_curvatures`).  Near-equal
    gaps are ordered by vertex index (:func:`stable_order`)."""
    gap, fit = curvature_gaps(model, geometry, x)
    chosen = first_per_cell(model, stable_order(gap), radius / spread)
    return chosen, gap[chosen], fit


def leading_places(gaps: np.ndarray, count: int | None, thin) -> np.ndarray:
    """``thin(stable_order(gaps))[:count]`` and maybe a few more (all of it for ``count`` None),
    where ``thin`` keeps, of vertices in order, the first of each place (:func:`first_per_cell`,
    :func:`first_per_place` without ``folded``): whether a vertex is kept depends on the vertices
    before it alone, so the places of the order's start are the start of its places.  Sorts the
    gaps' start alone, twice as far each time until ``count`` places are found."""
    n = len(gaps)
    head = n if count is None else min(n, max(1024, 8 * count))
    while True:
        order = stable_prefix(gaps, head)
        chosen = thin(order)
        if count is None or len(chosen) >= count or len(order) >= n:
            return chosen
        head = min(n, 2 * len(order))


def first_per_place(model: MeshModel, order: np.ndarray, size: float, angle: float, *,
                    folded: bool = False) -> np.ndarray:
    """Of the vertices ``order (n,)``, in that order, the first of each *place*: a cell of a grid
    ``size`` across and a direction of the fitted normal (:func:`first_per_direction`).  On a smooth
    surface a cell's normals lie within a few degrees and it is one place; on a sharp, thin or folded
    place (a crest, an edge, a leg a few millimetres thick) they span tens of degrees, and no one vertex
    poses the data for the rest (on the other-source P3 touches that ended on no fit, the cell's first
    vertex was 86-165 degrees off the true contact's normal).  With ``folded``, only the places of such
    *folded* cells (more than one direction)."""
    chosen = first_per_direction(_cells(model, order, size), model.fine_curvatures.normal[order], angle,
                                 folded=folded)
    return order[chosen]


def first_per_direction(cells: np.ndarray, normal: np.ndarray, angle: float, *, folded: bool = False) -> np.ndarray:
    """The positions, in order, of the first of each place among points in a chosen order, each in the
    cell ``cells (n,)`` (an integer key) with unit ``normal (n, 3)``: a cell's first point is a place;
    so is, in each direction bin (a Fibonacci sphere's cell, about ``angle`` degrees across), the first
    of the cell's points whose normal lies more than ``angle`` from its first's.  With ``folded``, only
    the places of cells with more than one direction."""
    _, first, inverse = np.unique(cells, return_index=True, return_inverse=True)
    head = normal[first][inverse]                                   # each point's cell's first
    off = np.nonzero(np.sum(normal * head, axis=1) < np.cos(np.deg2rad(angle)))[0]   # element-wise
    if len(off) == 0:
        return first[:0] if folded else np.sort(first)
    bins = fibonacci_sphere(max(12, int(round(4.0 * np.pi / np.deg2rad(angle) ** 2))))
    direction = np.argmax(np.einsum("nk,bk->nb", normal[off], bins), axis=1)      # no BLAS
    key = inverse[off].astype(np.int64) * len(bins) + direction
    _, extra = np.unique(key, return_index=True)
    chosen = np.sort(np.concatenate([first, off[extra]]))          # positions in the order
    if folded:
        fold = np.zeros(len(first), dtype=bool)
        fold[inverse[off]] = True
        chosen = chosen[fold[inverse[chosen]]]
    return chosen


def fibonacci_sphere(count: int) -> np.ndarray:
    """``count`` unit directions spread evenly over the sphere (a Fibonacci lattice), ``(count, 3)``."""
    i = np.arange(count) + 0.5
    polar, azimuth = np.arccos(1.0 - 2.0 * i / count), np.pi * (1.0 + np.sqrt(5.0)) * i
    return np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], axis=1)


#: the normal tilted four ways (rotation vectors about the frame's first two axes, per radian)
_TILTS = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]])


def frame_poses(model: MeshModel, geometry: LocalGeometry, chosen: np.ndarray, fit, *, rotations: str,
                umbilic: float, tilt: float = 0.0):
    """Step 2 at the vertices ``chosen (c,)``: poses ``R (h, 3, 3), t (h, 3)`` and the index into
    ``chosen`` each belongs to, ``owner (h,)``.

    The data's fitted normal (``fit``, from :func:`data_curvatures`) goes onto the vertex's
    fitted normal (both paraboloid fits at the same scale), the contact onto the vertex.
    ``rotations="frames"``: the data's first principal direction onto the vertex's, either way
    round, where both are defined (``|k1 - k2|`` of data and vertex at least ``umbilic``, in the
    model's inverse units); every 30 degrees where not.  ``"all"``: every 30 degrees at every
    place.  Scans start from well-defined tangents: the data's first curve, and at the vertex
    the coordinate axis least aligned with its normal, projected.  ``tilt`` (degrees) adds the
    normal tilted four ways."""
    field = model.fine_curvatures
    (dk1, dk2), direction, normal = fit
    n = field.normal[chosen]
    d1 = field.d1[chosen] - np.sum(field.d1[chosen] * n, axis=1, keepdims=True) * n
    d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
    frames = np.stack([d1, cross(n, d1), n], axis=2)                                     # (c, 3, 3) columns
    scan = np.ones(len(chosen), dtype=bool) if rotations == "all" else \
        (np.abs(field.k1[chosen] - field.k2[chosen]) < umbilic) | (abs(dk1 - dk2) < umbilic)
    fixed = np.stack(tangents(n) + (n,), axis=2)
    frames = np.where(scan[:, None, None], fixed, frames)
    counts = np.where(scan, 12, 2)
    owner = np.repeat(np.arange(len(chosen)), counts)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(counts) - counts, counts)
    R = compose(frames[owner], rotations_z(k * np.where(scan[owner], np.pi / 6, np.pi)))
    data_frame = np.where(scan[owner, None, None], local_frame(normal, geometry.tangents[0])[None],
                          local_frame(normal, direction)[None])
    if tilt > 0:
        T = rotations_from_vectors(np.deg2rad(tilt) * _TILTS)
        R = compose(R[:, None], T[None]).reshape(-1, 3, 3)
        owner = np.repeat(owner, len(T))
        data_frame = np.repeat(data_frame, len(T), axis=0)
    R = compose(R, data_frame)
    t = model.vertices[chosen][owner] - rotate(R, geometry.contact)
    return R, t, owner


def starting_poses(model: MeshModel, geometry: LocalGeometry, x: np.ndarray, *, count: int, spread: float = 4.0,
                   umbilic: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """The poses ``R (h, 3, 3), t (h, 3)`` posed by their frames at the best ``count`` places
    (steps 1-2), for other registrations to start from the same places."""
    radius = float(np.max(np.linalg.norm(x - geometry.contact, axis=1)))
    chosen, _, fit = places(model, geometry, x, radius, spread=spread)
    R, t, _ = frame_poses(model, geometry, chosen[:count], fit, rotations="frames", umbilic=umbilic / radius)
    return R, t


def contact_spread(model: MeshModel, R: np.ndarray, t: np.ndarray, x: np.ndarray, contact: np.ndarray) -> float:
    """How well the data ``x (m, 3)`` pin the contact under pose ``R (3, 3), t (3,)``: the root of the
    trace of the moved contact's covariance (model units), from the pose's covariance
    ``s^2 (J^T J)^-1`` at the fit (:func:`tactrec.registration.step.covariance`, the one
    point-to-plane Jacobian; ``s^2`` the residuals' variance).  Large where the data leave a
    direction free: along a cylinder's axis, over a flat patch."""
    moved = transform(R[None], t[None], x)
    residual, n = model.planes(moved)
    m = len(x)
    s2 = float(np.sum(residual[0] ** 2)) / max(m - 6, 1)
    cov = s2 * covariance(np.ascontiguousarray(moved[0]), np.ascontiguousarray(n[0], dtype=np.float64))
    p = rotate(R, contact) + t
    Jp = np.zeros((3, 6))
    Jp[:, :3] = -np.array([[0.0, -p[2], p[1]], [p[2], 0.0, -p[0]], [-p[1], p[0], 0.0]])
    Jp[:, 3:] = np.eye(3)
    return float(np.sqrt(max(np.sum(Jp * np.einsum("ij,jk->ik", Jp, cov)), 0.0)))


def registration(model: MeshModel, geometry: LocalGeometry, R: np.ndarray, t: np.ndarray, error: float, *,
                 candidates: int, sign: int = 1, scale: float = 1.0, x: np.ndarray | None = None) -> Registration:
    """The :class:`Registration` of pose ``R (3, 3), t (3,)`` with ``error`` (model units); with the
    data ``x``, also how well they pin the contact (:func:`contact_spread`)."""
    _, face, location = model.closest_points(rotate(R, geometry.contact)[None] + t)
    spread = 0.0 if x is None else contact_spread(model, R, t, x, geometry.contact)
    return Registration(model=model.name, error=float(error), location=location[0], rotation=R, translation=t,
                        candidates=candidates, site=np.array([float(face[0])]), phi=None, normal_sign=sign,
                        scale=scale, spread=spread)
