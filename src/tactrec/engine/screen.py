"""The engine's breadth generator: every place of a mesh at every rotation, screened on its distance field.

A hypothesis puts the touch's contact on a place of the model (a vertex,
the best of each grid cell ``step x radius`` across, so that places lie
about as far apart as a rotation step moves the curves' ends; in a cell
whose normals lie tens of degrees apart, on a crest or a thin part, the
best of each direction of them), the data's
fitted normal onto the place's fitted normal (both paraboloid fits at one
scale, :func:`tactrec.registration.mesh_fast.data_curvatures`), and turns the
data about it in ``rotations`` equal steps.  Each hypothesis is scored by
the mean truncated distance of a few points of each curve
(:func:`tactrec.engine.kernels.field_best`, about fifty times cheaper than
an exact query); the best ``keep`` go on to exact steps.  Places come in
the order of their curvature gap to the data, so a caller may screen them a
part at a time, most likely first.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..linalg import compose, rotate, stable_order, transform
from ..registration.result import local_frame, rotations_from_vectors
from ..surfaces.mesh_curvature import tangents
from .kernels import field_best, screen_rotations

__all__ = ["Screen", "screen", "screen_places", "data_normals", "tilt_rings", "tilted_normals", "local_screen",
           "local_lookups", "local_grid", "local_poses", "DISTINCT", "LOCAL_STEPS"]

#: values of each turn and shift of :func:`local_screen`'s grid about a pose (``LOCAL_STEPS**6`` poses)
LOCAL_STEPS = 5

#: data normals closer than this (degrees) pose the data alike: the refinement reaches across it
DISTINCT = 10.0



@dataclasses.dataclass(frozen=True)
class Screen:
    """The best hypotheses of a screen: poses ``R (k, 3, 3), t (k, 3)`` (data onto model), their
    field scores ``(k,)``, the place each belongs to (an index into the places screened) and the
    lookups spent."""

    R: np.ndarray
    t: np.ndarray
    score: np.ndarray
    owner: np.ndarray
    lookups: int


def screen_places(model, gap_order: np.ndarray, radius: float, *, step: float, angle: float,
                  folded: bool = False) -> np.ndarray:
    """The places to screen: of the vertices in the order ``gap_order`` (best curvature match first),
    the first of each grid cell ``step x radius`` across and of each direction of its normals
    ``angle`` degrees apart (:func:`tactrec.registration.mesh_fast.first_per_place`), in that order;
    with ``folded``, those of the cells with more than one direction alone."""
    from ..registration.mesh_fast import first_per_place

    return first_per_place(model, gap_order, max(step * radius, 1e-12), angle, folded=folded)


def _best_places(best: np.ndarray, keep: int) -> np.ndarray:
    """Indices of the ``keep`` places whose best rotation scores ``best (n,)`` least, best first (ties
    at the cut kept and ordered by index: :func:`tactrec.linalg.stable_order`)."""
    best = best.astype(np.float64)
    k = min(keep, len(best))
    part = np.arange(len(best))
    if k < len(best):
        part = np.argpartition(best, k - 1)[:k]
        part = np.flatnonzero(best <= best[part].max())
    return part[stable_order(best[part])][:k]


def _ends(curves, per_curve: int) -> np.ndarray:
    """``per_curve`` points of each curve, evenly spread along it without its middle (the contact,
    which every hypothesis puts on the surface): ``(k * per_curve, 3)``."""
    out = []
    for c in curves:
        c = np.asarray(c, dtype=np.float64)
        at = np.linspace(0, len(c) - 1, per_curve + 1 if per_curve % 2 else per_curve)
        if per_curve % 2:
            at = np.delete(at, len(at) // 2)
        out.append(c[np.unique(at.round().astype(int))])
    return np.concatenate(out)


def data_normals(geometry, fitted: np.ndarray, *, distinct: float, fine: np.ndarray | None = None) -> list[tuple]:
    """The data normals a touch is screened with, each with the model's normals it goes onto
    (``"fitted"``: each place's paraboloid fit; ``"ring"``: its one-ring normal, eq. 13): the fitted
    one onto the fitted ones (a paraboloid fit, as the model's places are fitted); the curves' own
    (eq. 1) where it differs from that by more than ``distinct`` degrees (a contact on a feature,
    where a fit at the paraboloid's scale smooths it away); and the finest scale's tangent cone
    (``fine``, :func:`tactrec.normal_scales.cone_normals`) onto the one-ring normals where it differs
    from both by more than ``distinct`` (a sharp, thin or folded place: only the first millimetre
    sees the surface there, as only the one ring does on the model)."""
    cos = np.cos(np.deg2rad(distinct))
    out = [(np.asarray(fitted, dtype=np.float64), "fitted")]
    if float(np.sum(geometry.normal * fitted)) < cos:       # element-wise: no BLAS
        out.append((np.asarray(geometry.normal, dtype=np.float64), "fitted"))
    if fine is not None and all(float(np.sum(fine * n)) < cos for n, _ in out):
        out.append((np.asarray(fine, dtype=np.float64), "ring"))
    return out


def tilt_rings(*, cone: float, step: float) -> list[tuple[float, int]]:
    """The rings of :func:`tilted_normals`: each ring's tilt (radians) and how many normals it holds."""
    rings = np.arange(1, int(np.floor(cone / step + 1e-9)) + 1) * np.deg2rad(step)
    return [(float(a), max(6, int(round(2.0 * np.pi * np.sin(a) / np.deg2rad(step))))) for a in rings]


def tilted_normals(normal: np.ndarray, reference: np.ndarray, *, cone: float, step: float) -> list[np.ndarray]:
    """Data normals tilted off ``normal (3,)`` on rings ``step, 2 step, ...`` degrees out to ``cone``,
    each ring at about ``step`` apart (at least six), azimuth 0 towards ``reference (3,)``: the
    hypotheses of a contact whose normal the data do not give (a sharp or thin feature, where any
    fit of the curves is tens of degrees off the surface's normal).  The untilted normal is not
    among them."""
    L = local_frame(np.asarray(normal, dtype=np.float64), np.asarray(reference, dtype=np.float64))   # rows t1 t2 N
    out = []
    for ring, count in tilt_rings(cone=cone, step=step):
        for a in 2.0 * np.pi * np.arange(count) / count:
            v = np.array([np.sin(ring) * np.cos(a), np.sin(ring) * np.sin(a), np.cos(ring)])
            out.append(v[0] * L[0] + v[1] * L[1] + v[2] * L[2])                         # element-wise: no BLAS
    return out


def local_grid(angle: float, shift: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The turns ``(steps**3, 3, 3)`` of up to ``angle`` degrees about three axes and the shifts
    ``(steps**3, 3)`` of up to ``shift`` along them, ``steps`` values of each: a grid of ``steps**6``
    poses about one (:func:`local_screen`, :func:`local_poses`)."""
    a = np.deg2rad(np.linspace(-angle, angle, steps))
    turns = rotations_from_vectors(np.stack(np.meshgrid(a, a, a, indexing="ij"), -1).reshape(-1, 3))
    d = np.linspace(-shift, shift, steps)
    return turns, np.stack(np.meshgrid(d, d, d, indexing="ij"), -1).reshape(-1, 3)


def local_poses(R: np.ndarray, t: np.ndarray, contact: np.ndarray, *, angle: float, shift: float,
                steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pose of :func:`local_grid` about each pose ``R (s, 3, 3), t (s, 3)``, turned about the
    contact's image: ``R (s * steps**6, 3, 3), t (s * steps**6, 3)``, seed by seed."""
    turns, shifts = local_grid(angle, shift, steps)
    pivot = rotate(R, contact) + t                                                     # (s, 3)
    turned = compose(turns[None], R[:, None]).reshape(-1, 3, 3)                        # (s * k, 3, 3)
    Rg = np.repeat(turned, len(shifts), axis=0)
    tg = (np.repeat(pivot, len(turns) * len(shifts), axis=0) + np.tile(shifts, (len(R) * len(turns), 1))
          - rotate(Rg, contact))
    return Rg, tg


def local_lookups(seeds: int, points: int, *, steps: int = LOCAL_STEPS) -> int:
    """The field lookups of :func:`local_screen` about ``seeds`` poses scored on ``points`` points."""
    return int(seeds * steps ** 6 * points)


def local_screen(model, R: np.ndarray, t: np.ndarray, x: np.ndarray, contact: np.ndarray, *, angle: float,
                 shift: float, steps: int = LOCAL_STEPS) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """A dense grid about each pose ``R (s, 3, 3), t (s, 3)``: turns of up to ``angle`` degrees about
    the three axes through the contact's image and shifts of up to ``shift`` along them, ``steps``
    values of each (``steps**6`` poses a seed), scored on the field by the data ``x (m, 3)``.  It
    bridges the gap between a coarse grid of hypotheses (places, tilts) and the basin of the
    Gauss-Newton steps, which on a faceted surface is a few degrees wide.  Returns each seed's best
    pose ``R (s, 3, 3), t (s, 3)``, its field score ``(s,)`` and the lookups spent."""
    turns, shifts = local_grid(angle, shift, steps)
    eye = np.ascontiguousarray(np.broadcast_to(np.eye(3), (len(shifts), 3, 3)))
    field = model.distance_field
    Rb, tb, sb = np.empty_like(R), np.empty_like(t), np.empty(len(R))
    for s in range(len(R)):
        pivot = rotate(R[s], contact) + t[s]
        turned_R = compose(turns, R[s][None])
        turned = np.ascontiguousarray(transform(turned_R, np.zeros((len(turns), 3)), x - contact))  # (r, m, 3)
        best, which = field_best(*field.args(), eye, np.ascontiguousarray(pivot + shifts), turned)
        i = int(stable_order(best.astype(np.float64))[0])
        Rb[s] = turned_R[which[i]]
        tb[s] = pivot + shifts[i] - rotate(Rb[s], contact)
        sb[s] = best[i]
    return Rb, tb, sb, local_lookups(len(R), len(x), steps=steps)


def screen(model, geometry, vertices: np.ndarray, normals: np.ndarray, curves, normal: np.ndarray, *, stages,
           keep: int, extra: np.ndarray | None = None) -> Screen:
    """Screen the data ``curves`` (data frame) at the spots ``vertices (n,)``, ``normals (n, 3)`` of a
    mesh model: a data ``normal (3,)`` (or each of ``(k, 3)``) onto the spot's normal,
    ``geometry.contact`` onto the vertex, turned about it.  ``stages``, coarse to fine, are
    ``(rotations, points a curve, share kept)``: each scores the spots the last kept at
    ``rotations`` equal turns (about each data normal) on that many points of each curve
    (:func:`_ends`) and keeps that share of them (at least ``keep``); the last stage's best
    ``keep`` spots go on, each at its best normal and turn, ordered by score (near-equal scores by
    index: :func:`tactrec.linalg.stable_order`).  ``owner`` indexes the spots.  ``extra (k, 3)``:
    points scored at every stage besides the curves' (a session's other touches, one point a
    curve: the screen then costs about what the touch alone costs)."""
    field = model.distance_field
    data = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    L0 = np.stack([local_frame(n, geometry.tangents[0]) for n in data])                # (k, 3, 3) rows t1, t2, N
    d1, d2 = tangents(normals)
    frames_all = np.ascontiguousarray(np.stack([d1, d2, normals], axis=2))              # (n, 3, 3) columns
    alive = np.arange(len(vertices))
    lookups = 0
    for k, (rotations, per_curve, share) in enumerate(stages):
        frames = np.ascontiguousarray(frames_all[alive])
        points = _ends(curves, per_curve) if extra is None else np.concatenate([_ends(curves, per_curve), extra])
        turned = np.concatenate([screen_rotations(np.ascontiguousarray(rotate(L, points - geometry.contact)),
                                                  rotations) for L in L0])              # element-wise: no BLAS
        best, arg = field_best(*field.args(), frames, np.ascontiguousarray(model.vertices[vertices[alive]]), turned)
        lookups += best.size * turned.shape[0] * len(points)
        last = k == len(stages) - 1
        chosen = _best_places(best, keep if last else max(keep, int(np.ceil(share * len(alive)))))
        if not last:
            alive = alive[chosen]
    which, turn = np.divmod(arg[chosen], rotations)
    score = best[chosen].astype(np.float64)
    angle = 2.0 * np.pi * turn / rotations
    c, s = np.cos(angle), np.sin(angle)
    Rz = np.zeros((len(chosen), 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    R = compose(compose(frames[chosen], Rz), L0[which])
    t = model.vertices[vertices[alive[chosen]]] - rotate(R, geometry.contact)
    return Screen(R, t, score, alive[chosen], int(lookups))
