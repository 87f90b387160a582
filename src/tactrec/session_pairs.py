"""Step 5 of a session (:mod:`tactrec.session`): poses from a pair of touches, over every place.

A touch's own search ranks a model's places by how well their curvatures
match the touch's; on a short noisy touch the curvatures say little and the
true place can rank in the thousands, beyond any budget.  Two touches of one
still object in one frame need no curvature: their contacts ``c_i, c_j`` and
normals ``n_i, n_j`` fix the pose.

The model is sampled evenly over its surface (its
:meth:`~tactrec.surfaces.base.SurfaceModel.oriented_samples`: a mesh, as many
samples as it has vertices, with the vertex normals interpolated; a
closed-form surface, 6000 seeded sites).  Each sample's *turn* is the largest angle
between its normal and its neighbours' (either sign: a thin wall's two sides
are not neighbours): it bounds how far the normal of a point between samples
is from theirs.  Put touch ``i``'s contact on a place ``a`` (one sample per
cell :data:`PLACE_CELL` spacings across) with its normal onto the place's
normal: one turn ``theta`` about that normal is left, and under it touch
``j``'s contact runs round a circle about ``a``.  ``theta`` is stepped so that
the contact (or a point of touch ``i`` at its reach) moves one spacing a
step.  A pose is a *candidate* where the circle passes near a sample (one
spacing, plus how far a tilt of ``n_i`` within the place's tolerance moves
``c_j``) whose normal agrees with ``n_j`` turned the same way (either sign)
within :data:`NORMAL_ERROR` plus the two samples' turns.  Both signs of
``n_i`` are tried.

The candidates are then scored as a touch's own search scores its poses
(:mod:`tactrec.methods.fast`): the curves' ends against the samples' tangent
planes, the best eighth (at least ``screen``) two Gauss-Newton steps on a few
points of every curve, the best ``refine`` refined on three times the
points and the best of them on all points.  The model's best pose and the
others refined are returned as a
:class:`~tactrec.registration.result.Registration` with ``alternatives``, as
a search would, and the session's joint fit (step 2) takes them up.

The models are posed :data:`BATCH` at a time, in the order of the session's
joint fits, the best first.  The search stops after a batch in which some
pose fits the touches at their noise (the session's own test for starting
it): then no pose can fit them better than their noise allows, and the
models left are not posed.  When the leading model is the true one and only
its pose was off, the search costs a batch, not every model.  A session
also gives it a budget of work (:mod:`tactrec.session`, step 5): it stops
after the batch that spends it.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from .features import subset
from .linalg import compose, rotate, stable_order, transform
from .registration.result import Registration
from .registration.solver import Criteria, solve
from .session_fit import refine
from .surfaces.mesh_curvature import tangents

__all__ = ["PairSearch", "pair_stage", "search", "turns", "CHUNK", "BATCH", "PLACE_CELL", "NORMAL_ERROR"]

#: (place, turn) pairs handled at once
CHUNK = 200_000
#: models a pair search poses at once (a constant, so which models it searches is the same on any
#: number of worker processes), before it asks whether a pose fits the touches at their noise
BATCH = 4
#: places for touch i: one sample per cubic cell this many sample spacings across
PLACE_CELL = 2.0


@dataclasses.dataclass(frozen=True)
class PairSearch:
    """The outcome of a pair search: per model its best pose and the others refined (``ranking``,
    as a :class:`~tactrec.recognition.Recognition` has), and the closest-point queries spent."""

    ranking: list
    work: int
    pair: tuple


def turns(normals: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Per sample ``(n,)``, radians: the largest angle between its normal ``normals (n, 3)`` and its
    neighbours' (``pairs (p, 2)`` of sample indices): how far the model's normal field turns from
    one sample to the next, which bounds how far a touch's normal between samples is from theirs."""
    angle = np.arccos(np.clip(np.abs(np.sum(normals[pairs[:, 0]] * normals[pairs[:, 1]], axis=1)), 0.0, 1.0))
    out = np.zeros(len(normals))
    np.maximum.at(out, pairs[:, 0], angle)
    np.maximum.at(out, pairs[:, 1], angle)
    return out


class _Samples(NamedTuple):
    """A model's oriented samples (model units), built once per model and process."""

    points: np.ndarray          # (n, 3)
    normals: np.ndarray         # (n, 3), unit
    turn: np.ndarray            # (n,) radians, :func:`turns`
    spacing: float
    tree: object                # k-d tree of the points
    places: np.ndarray          # (p,) the samples a touch's contact is put on, one per cell
    t1: np.ndarray              # (n, 3) tangents completing each normal to a frame
    t2: np.ndarray              # (n, 3)


def _oriented_points(model) -> _Samples:
    """A model's oriented samples (module text)."""
    from scipy.spatial import cKDTree

    points, normals = model.oriented_samples(rng=0)
    tree = cKDTree(points)
    spacing = 1.5 * float(np.median(tree.query(points, k=2)[0][:, 1]))
    cell = np.floor((points - points.min(axis=0)) / (PLACE_CELL * spacing)).astype(np.int64)
    places = np.sort(np.unique(cell, axis=0, return_index=True)[1])
    return _Samples(points, normals, turns(normals, tree.query_pairs(spacing, output_type="ndarray")), spacing,
                    tree, places, *tangents(normals))


def _candidates(samples: _Samples, error, ci, ni, cj, nj, reach):
    """Poses ``R (h, 3, 3), t (h, 3)`` (model = R data + t) that put contact ``ci`` on one of the
    ``samples``' places with normal ``ni`` onto its normal and contact ``cj`` near a sample (the
    spacing, plus how far a tilt of ``ni`` by ``error`` and the place's turn moves ``cj``) whose
    normal agrees with ``nj`` (either sign) within ``error`` and the two samples' turns; see the
    module text.  The turn is stepped so that ``cj``, or a point ``reach`` from ``ci`` when that
    is farther, moves at most the spacing a step."""
    points, normals, turn, spacing, tree, places, t1, t2 = samples
    e1, e2 = (v[0] for v in tangents(ni[None]))
    Fi = np.stack([e1, e2, ni], axis=1)                                     # touch frame, columns
    v = (cj - ci) @ Fi                                                      # (x, y, z) in it
    rho, psi = float(np.hypot(v[0], v[1])), float(np.arctan2(v[1], v[0]))
    steps = max(12, int(np.ceil(2 * np.pi * max(rho, reach) / spacing)))
    theta = 2 * np.pi * np.arange(steps) / steps
    nj_local = nj @ Fi                                                      # (3,)
    cos, sin = np.cos(theta + psi), np.sin(theta + psi)
    found = []
    per = max(1, CHUNK // steps)
    for lo in range(0, len(places), per):
        a = places[lo:lo + per]
        p = points[a, None] + v[2] * normals[a, None] \
            + rho * (cos[None, :, None] * t1[a, None] + sin[None, :, None] * t2[a, None])   # (k, s, 3)
        # a tilt of touch i's normal within the place's tolerance moves touch j's contact this far
        tilt = np.minimum(error + turn[a], np.pi / 2)
        near = spacing + np.hypot(rho, v[2]) * np.sin(tilt)
        d, b = tree.query(p.reshape(-1, 3), distance_upper_bound=float(near.max()))
        which = np.nonzero(d <= np.repeat(near, steps))[0]
        ka, ks, kb = a[which // steps], which % steps, b[which]
        # touch j's normal, turned by theta about touch i's normal, in the place's frame
        c, s = np.cos(theta[ks]), np.sin(theta[ks])
        local = np.stack([c * nj_local[0] - s * nj_local[1], s * nj_local[0] + c * nj_local[1],
                          np.full(len(ks), nj_local[2])], axis=1)
        turned = local[:, :1] * t1[ka] + local[:, 1:2] * t2[ka] + local[:, 2:] * normals[ka]
        agree = np.abs(np.sum(turned * normals[kb], axis=1)) >= np.cos(np.minimum(error + turn[ka] + turn[kb], np.pi))
        found.append((ka[agree], ks[agree]))
    ka, ks = (np.concatenate([f[k] for f in found]) for k in range(2))
    if not len(ka):
        return np.empty((0, 3, 3)), np.empty((0, 3))
    c, s = np.cos(theta[ks]), np.sin(theta[ks])
    Rz = np.zeros((len(ks), 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    Fa = np.stack([t1[ka], t2[ka], normals[ka]], axis=2)                   # (h, 3, 3) columns
    R = compose(compose(Fa, Rz), Fi.T[None])
    return R, points[ka] - rotate(R, ci)


def pair_stage(held, indices, touches: list, pair: tuple, normal_error: float, options: dict) -> list:
    """Per model at ``indices``: the pair search (module text) from touches ``pair = (i, j)`` of
    ``touches`` (per touch ``(curves, contact (3,), normal (3,))``, data units), poses scored on
    every touch's curves.  ``options``: the scoring's ``coarse_points``, ``screen``, ``refine``,
    ``iterations`` and ``scale`` (per index, data to model units).  Returns per model ``(R (k, 3, 3),
    t (k, 3), error (k,), queries)``, best first (error in data units), or None when no pose
    qualified."""
    out = []
    for index in indices:
        model = held.entries[index].model
        scale = options["scale"][index]
        key = ("pairs", index)
        if key not in held.samples:
            held.samples[key] = _oriented_points(model)
        samples = held.samples[key]
        (first, ci, ni), (_, cj, nj) = touches[pair[0]], touches[pair[1]]
        reach = scale * max(float(np.max(np.linalg.norm(c - ci, axis=1))) for c in first)
        R, t = [], []
        for sign in (1.0, -1.0):
            Rs, ts = _candidates(samples, normal_error, ci * scale, sign * ni, cj * scale, nj, reach)
            R.append(Rs)
            t.append(ts)
        R, t = np.concatenate(R), np.concatenate(t)
        if not len(R):
            out.append(None)
            continue
        curves = [c * scale for curves, _, _ in touches for c in curves]
        out.append(_scored(model, samples, R, t, curves, options, scale))
    return out


def _scored(model, samples: _Samples, R, t, curves, options, scale):
    """The candidates ``R, t`` scored on ``curves`` (model units) and refined (module text):
    ``R, t, error`` (data units) best first, and the closest-point queries spent."""
    ends = subset(curves, 2)
    x = np.concatenate(curves)
    points, normals, tree = samples.points, samples.normals, samples.tree

    def plane(x):                           # distance to the nearest sample's tangent plane
        _, b = tree.query(x)
        return np.abs(np.sum((x - points[b]) * normals[b], axis=1))

    per = CHUNK // len(ends)
    screen = np.concatenate([plane(transform(R[lo:lo + per], t[lo:lo + per], ends).reshape(-1, 3))
                             .reshape(-1, len(ends)).mean(axis=1) for lo in range(0, len(R), per)])
    keep = stable_order(screen)[:max(options["screen"], len(R) // 8)]
    queries = len(R) * len(ends)
    coarse = subset(curves, options["coarse_points"])
    R, t, score, q = solve(model, R[keep], t[keep], coarse, Criteria(2, predict=True))
    queries += q
    keep = stable_order(score)[:options["refine"]]
    fine = subset(curves, 3 * options["coarse_points"])
    R, t, error = refine(model, R[keep], t[keep], fine, options["iterations"])
    queries += (options["iterations"] + 1) * len(keep) * len(fine)
    order = stable_order(error)
    R, t, error = R[order], t[order], error[order]
    Rb, tb, eb = refine(model, R[:1], t[:1], x, options["iterations"])
    if eb[0] < error[0]:
        R, t, error = np.concatenate([Rb, R[1:]]), np.concatenate([tb, t[1:]]), np.concatenate([eb, error[1:]])
    return R, t, error / scale, queries + (options["iterations"] + 1) * len(x)


#: a touch's fitted normal is taken to be within this angle (radians) of the model's normal at its
#: contact, besides how far the surface turns between samples (:func:`turns`)
NORMAL_ERROR = np.deg2rad(5.0)


def search(session, keep: list, *, budget: float = np.inf) -> PairSearch | None:
    """The pair search (module text) for a :class:`~tactrec.session.Session`: the newest of the
    touches ``keep`` (indices, oldest first) paired with the one of them farthest from it (the
    turn is best pinned by a long pair), poses scored on the touches ``keep``, in the recognizer's
    worker processes.  The models are searched :data:`BATCH` at a time, in the order of the
    session's joint fits (the best first, then those without one), until a batch yields a pose
    that fits the touches at their noise (:meth:`~tactrec.session.Session.fitted_at`): the rule
    that starts the search ends it; or until its work (closest-point queries) reaches ``budget``,
    checked after each batch.  None with fewer than two touches."""
    from .methods.common import in_model_units
    from .registration.mesh_fast import data_curvatures

    if len(keep) < 2:
        return None
    touches = []
    for i in keep:
        f = session.features[i]
        normal = data_curvatures(f.geometry, f.points, f.radius)[2]
        touches.append((f.curves, f.geometry.contact, normal))
    far = int(np.argmax([np.linalg.norm(c - touches[-1][1]) for _, c, _ in touches[:-1]]))
    config, models = session.recognizer.config, session.recognizer.models
    options = {name: getattr(config, name, default) for name, default in
               (("coarse_points", 5), ("screen", 96), ("refine", 8), ("iterations", 20))}
    options["scale"] = {i: in_model_units(session.features[keep[-1]], e.model).scale for i, e in enumerate(models)}
    ranked = {} if session.result is None else {h.model: k for k, h in enumerate(session.result.ranking)}
    order = sorted(range(len(models)), key=lambda i: (ranked.get(models[i].name, len(ranked)), i))
    ranking, work = [], 0
    for lo in range(0, len(order), BATCH):
        batch = order[lo:lo + BATCH]
        found = session.recognizer.runner.map(pair_stage, batch, touches, (len(keep) - 1, far), NORMAL_ERROR,
                                              options)
        fitted = False
        for i, poses in zip(batch, found):
            e = models[i]
            if poses is None:
                ranking.append(Registration.rejection(e.name, "no pose puts both contacts on the surface"))
                continue
            R, t, error, queries = poses
            s = options["scale"][i]
            ranking.append(Registration(model=e.name, error=float(error[0] * s), rotation=R[0], translation=t[0],
                                        scale=s, candidates=len(R),
                                        alternatives=np.concatenate([R[1:], t[1:, :, None]], axis=2)))
            work += queries
            fitted = fitted or session.fitted_at(float(error[0]), keep)
        if fitted or work >= budget:
            break
    return PairSearch(ranking, int(work), (keep[-1], keep[far]))
