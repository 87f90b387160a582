"""Hypotheses from single contacts: poses from triangles of contacts, screened on a mesh's field.

A touch of contacts (:mod:`tactrec.io.contacts`) has no curvature to look
up; what it has is distances.  Three contacts ``a, b, c`` span a triangle
whose sides no pose changes, so each of the model's triangles of places
with the same sides poses the data: ``a, b, c`` onto the three places, by
the frames the triangles span (no fit, no BLAS).  A contact's normal is a
rotation-free test too: each normal's angle to the chord between two
contacts, and the angle between their normals, are the same on the model
within their stated uncertainty (:data:`ANGLE` standard deviations; a normal
given without one tests nothing).

Per model the search (:func:`contact_stage`):

1. places: of :data:`DENSE` x :data:`PLACES` points uniform over the mesh's
   area (seeded; a mesh's vertices need not cover its surface), the first of
   each grid cell (about :data:`PLACES` cells) and, in a cell whose points'
   normals lie more than :data:`FOLD` degrees apart (a thin wall's two
   sides, an edge's two faces), the first of each direction of them (the
   curves' rule, :func:`tactrec.registration.mesh_fast.first_per_direction`),
   each with its face's normal.  ``reach``, the farthest any of the points
   lies from its nearest place whose normal is within :data:`FOLD` of its
   own (among the :data:`NEAR` nearest; else the place of its cell whose
   normal is nearest its own), bounds how far a contact lies from a place
   that can pose it, so a pair of places matches a pair of contacts whose
   distance is within ``2 reach`` (and three of the points' standard
   deviations) of theirs.  Their normals are tested with the contacts' own
   uncertainty alone, not with how far a place's normal and chord may turn
   from its contact's: allowing for that (up to :data:`FOLD` and
   ``asin(2 reach / distance)``) makes the tests a bound, but a power
   drill's four contacts then pose 150 million triangles in 46 s, against
   15 thousand in 0.7 s.  So they screen, and how often the search misses
   the touched model is measured (``docs/benchmarks.md``);
2. for each of up to :data:`TRIANGLES` triangles of contacts (the largest
   first, then the largest with a new corner), takes every pair of places
   matching ``a`` and ``b`` (and alike in normals), joins the pairs that
   share ``a``'s place with those matching ``a`` and ``c``, keeps the joins
   whose third side matches, and poses each (:data:`CHUNK` at a time);
3. screens every pose on the distance field by all contacts and their
   normals (mean truncated distance, in the same compiled pass that poses
   them, :func:`tactrec.engine.kernels.triangle_screen`; a pose's sum stops
   once it can no longer be among the best :data:`FIELD_KEEP`), gives the
   best :data:`FIELD_KEEP` :data:`FIELD_STEPS` steps on the field
   (:func:`~tactrec.engine.kernels.field_refine`) and refines :data:`KEEP`
   of those on exact distances (:func:`tactrec.registration.solver.solve`):
   the best of those whose normals agree with the contacts' (the test of
   step 4, :func:`_kept`), then the best of the others.  A normal takes part in
   these steps as four points on the contact's tangent plane
   (:func:`tangent_points`), each where a tilt of one standard deviation
   lifts it by the touch's fit limit: a pose that turns the
   normal off the model's lifts them off the surface, so the one
   point-to-plane step fits positions and normals together, each weighed by
   its uncertainty.  Three contacts fit a family of poses by their distances
   alone, and distances alone would slide a start along it to any of them;
4. keeps the pose of least mean distance among those whose normals agree
   with the model's (:func:`_agree`: a chi-square test of their angles
   under their stated uncertainties); the others that agree are its
   alternatives.  Once a triangle's best such pose is a fit (within the
   touch's plausible fit), no further triangle is posed.

A model whose places hold no such triangle, or none of whose refined poses
agrees with the contacts' normals, is rejected: six or fewer contacts fit
almost any smooth surface by their distances alone (a pose has six degrees of
freedom), and it is their normals that rule a model out.
"""

from __future__ import annotations

import math

import numpy as np

from ..linalg import rotate, stable_order, tangents, transform
from ..registration.result import Outcome, Registration

__all__ = ["contact_stage", "tangent_points", "triangles", "PLACES", "DENSE", "FOLD", "NEAR", "FIELD_KEEP",
           "FIELD_STEPS", "KEEP", "TRIANGLES", "SIGMAS", "ANGLE", "CHUNK"]

#: about this many places per model (one per grid cell): the pairs of places number its square
PLACES = 800
#: points sampled per place, uniform over the area: what the places are chosen from and posed contacts tested on
DENSE = 20
#: a cell whose points' normals lie more than this many degrees from its first's has a place per direction of
#: them: a fold (a thin wall's two sides lie 180 degrees apart, an edge's faces 90).  A rough scan's facets within
#: a cell seldom lie so far apart; at the curves' 20 degrees the strawberry's places grow from 1,064 to 2,803 and
#: a search of three of its contacts takes eight times as long
FOLD = 60.0
#: the places each point's nearest alike place is sought among (its own cell's place bounds it otherwise)
NEAR = 8
#: poses per model that take steps on the distance field (the best by the field's screen)
FIELD_KEEP = 1000
#: their steps
FIELD_STEPS = 10
#: poses per model refined on exact distances
KEEP = 24
#: triangles of contacts posed per model (each a different third corner)
TRIANGLES = 3
#: a normal agrees within this many of its standard deviations (the fit test's allowance)
SIGMAS = 3.0
#: a normal's angle to the truth is within this many of its standard deviations but for the fit test's
#: tail: the root of the chi-square quantile of two degrees of freedom at SIGMAS normal deviations out
ANGLE = float(np.sqrt(-2.0 * np.log(0.5 * math.erfc(SIGMAS / math.sqrt(2.0)))))
#: triangles of places posed and screened at a time
CHUNK = 200_000
#: exact refinement steps
STEPS = 30


def tangent_points(x: np.ndarray, normals: np.ndarray, sd: np.ndarray, fit: float) -> np.ndarray:
    """The contacts ``x (n, 3)`` and, for each with a normal and its uncertainty ``sd`` (degrees), four
    points on its tangent plane, ``+-s`` along two directions across the normal, ``s = fit /
    radians(sd)``: a tilt of one standard deviation lifts them by ``fit`` (data units, the touch's fit
    limit), what a point's noise moves it by.  ``(n + 4 k, 3)``, the contacts first."""
    use = np.isfinite(normals[:, 0]) & np.isfinite(sd) & (sd > 0) if fit > 0 else np.zeros(len(x), dtype=bool)
    d1, d2 = tangents(normals[use])
    s = (float(fit) / np.radians(sd[use]))[:, None]
    p = x[use]
    return np.concatenate([x, np.stack([p + s * d1, p - s * d1, p + s * d2, p - s * d2], axis=1).reshape(-1, 3)])


def triangles(points: np.ndarray, count: int) -> list[tuple[int, int, int]]:
    """Up to ``count`` triangles of the contacts ``points (n, 3)``: the largest, then each the largest
    with a corner none before had (ties by index).  A triangle of zero area is never one."""
    n = len(points)
    i, j, k = np.array([(i, j, k) for i in range(n) for j in range(i + 1, n) for k in range(j + 1, n)]).T
    area = 0.5 * np.linalg.norm(np.cross(points[j] - points[i], points[k] - points[i]), axis=1)
    order = stable_order(-area)
    out, used = [], set()
    for q in order:
        tri = (int(i[q]), int(j[q]), int(k[q]))
        if area[q] <= 0 or (out and set(tri) <= used):
            continue
        out.append(tri)
        used |= set(tri)
        if len(out) == count:
            break
    return out


def _places(model):
    """The mesh ``model``'s places for contacts, built once (module text, step 1): positions ``(p, 3)``,
    their faces' normals ``(p, 3)`` and ``reach``, the farthest any of the dense points lies from its
    nearest place of a normal alike (or its own place, :func:`_own_places`), model units."""
    from scipy.spatial import cKDTree

    from ..registration.mesh_fast import first_per_direction
    from ..surfaces.mesh_grid import grid_keys
    from ..surfaces.mesh_table import area_samples

    memo = model.search_memo
    if "contact_places" not in memo:
        dense, normals = area_samples(model, DENSE * PLACES, np.random.default_rng(0))
        size = float(np.sqrt(model.area / PLACES))
        key = grid_keys(dense, dense.min(axis=0), dense.max(axis=0), size)
        chosen = first_per_direction(key, normals, FOLD)
        P, N = dense[chosen], normals[chosen]
        # each point's nearest place of a normal within FOLD of its own, else its own place (its cell's)
        own = np.linalg.norm(dense - dense[_own_places(key, normals, chosen)], axis=1)
        d, j = cKDTree(P).query(dense, k=min(NEAR, len(P)))
        d, j = d.reshape(len(dense), -1), j.reshape(len(dense), -1)
        alike = np.sum(normals[:, None, :] * N[j], axis=2) >= np.cos(np.radians(FOLD))
        reach = float(np.minimum(np.where(alike, d, np.inf).min(axis=1), own).max())
        memo["contact_places"] = (P, N, reach)
    return memo["contact_places"]


def _own_places(key: np.ndarray, normals: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    """Each point's own place ``(n,)``, an index of the points: of the places ``chosen`` in its cell
    (``key``), the one whose normal is nearest its own (the first of equals)."""
    order = chosen[np.argsort(key[chosen], kind="stable")]
    lo = np.searchsorted(key[order], key, side="left")
    count = np.searchsorted(key[order], key, side="right") - lo
    own, best = order[lo], np.sum(normals * normals[order[lo]], axis=1)
    for j in range(1, int(count.max())):
        has = np.flatnonzero(count > j)
        other = order[lo[has] + j]
        cos = np.sum(normals[has] * normals[other], axis=1)
        better = cos > best[has]
        own[has[better]], best[has[better]] = other[better], cos[better]
    return own


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The angle between unit rows ``u`` and ``v``, degrees (element-wise: no BLAS)."""
    return np.degrees(np.arccos(np.clip(np.sum(u * v, axis=-1), -1.0, 1.0)))


def _pairs(P, N, length: float, tol: float, na, nb):
    """The ordered pairs of distinct places ``(v, w)`` as far apart as ``length`` (within ``tol``) whose
    normals make the angles the contacts' normals make with the chord between them and with each other:
    ``na``, ``nb`` (each None or ``(normal, angle to the chord, allowance in degrees)``), in one
    compiled pass (:func:`tactrec.engine.kernels.place_pairs`).  Returns ``v (q,), w (q,)``."""
    from .kernels import place_pairs

    ends = np.full(6, -1.0)
    if na is not None:
        ends[0:2] = na[1], na[2]
    if nb is not None:
        ends[2:4] = nb[1], nb[2]
    if na is not None and nb is not None:
        ends[4:6] = float(_angle(na[0], nb[0])), float(np.hypot(na[2], nb[2]))
    return place_pairs(np.ascontiguousarray(P), np.ascontiguousarray(N), float(length), float(tol), ends)


def _frames(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The frames ``(..., 3, 3)`` (columns: along ``ab``, in the plane towards ``c``, the plane's normal)
    of triangles ``a, b, c (..., 3)``; element-wise arithmetic."""
    e1 = b - a
    e1 = e1 / np.linalg.norm(e1, axis=-1, keepdims=True)
    e3 = np.cross(e1, c - a)
    e3 = e3 / np.maximum(np.linalg.norm(e3, axis=-1, keepdims=True), 1e-300)
    return np.stack([e1, np.cross(e3, e1), e3], axis=-1)


def _triangle_screen(field, P, N, x, xa, normals, sd, tri, tol):
    """Every pose putting the contacts ``tri = (a, b, c)`` of ``x`` on a triangle of places with the same
    sides (within ``tol``) and normals alike (:func:`_pairs`), screened on
    ``field`` by the points ``xa`` (:func:`tangent_points`) in parts of about :data:`CHUNK` triangles (so
    that a model whose places hold millions of such triangles is screened in bounded memory and compiled
    code, :func:`tactrec.engine.kernels.triangle_screen`).  Once :data:`FIELD_KEEP` poses are held, a
    pose's sum stops past the worst of them, which it can then no longer displace.  Returns the best
    :data:`FIELD_KEEP` poses (the first of equal scores) ``R (h, 3, 3), t (h, 3), score (h,)`` and how
    many triangles were posed."""
    from .kernels import triangle_poses, triangle_screen

    a, b, c = tri

    def side(i, j):
        length = float(np.linalg.norm(x[j] - x[i]))
        u = (x[j] - x[i]) / length
        ends = [None if not (np.isfinite(normals[k, 0]) and np.isfinite(sd[k])) else
                (normals[k], float(_angle(normals[k], u)), ANGLE * float(sd[k])) for k in (i, j)]
        return _pairs(P, N, length, tol, *ends)

    none = np.zeros(0, dtype=np.int64)
    held, score, tried = (none, none, none), np.zeros(0, dtype=np.float32), 0
    data_frame = np.ascontiguousarray(_frames(x[a], x[b], x[c]))
    v1, w1 = side(a, b)
    v2, w2 = side(a, c)
    if len(v1) and len(v2):
        # join the pairs that share a's place: each (v, w) of ab with each (v, u) of ac
        o1, o2 = np.argsort(v1, kind="stable"), np.argsort(v2, kind="stable")
        v1, w1, v2, w2 = v1[o1], w1[o1], v2[o2], w2[o2]
        first = np.searchsorted(v2, v1, side="left")
        count = np.searchsorted(v2, v1, side="right") - first
        ends = np.cumsum(count)
        bc = float(np.linalg.norm(x[c] - x[b]))
        # the triangle's own contacts last: every pose puts them on the surface, so the others decide early
        rest = np.ones(len(xa), dtype=bool)
        rest[list(tri)] = False
        screened = np.ascontiguousarray(np.concatenate([xa[rest], xa[list(tri)]]))
        lo = 0
        while lo < len(v1):
            hi = max(lo + 1, int(np.searchsorted(ends, (ends[lo - 1] if lo else 0) + CHUNK, side="right")))
            offset = ends[lo:hi] - count[lo:hi] - (ends[lo - 1] if lo else 0)
            bound = float(score.max()) if len(score) == FIELD_KEEP else np.inf
            part = triangle_screen(*field.args(), P, v1[lo:hi], w1[lo:hi], w2, first[lo:hi], count[lo:hi], offset,
                                   bc, tol, data_frame, x[a], screened, bound)
            tried += int(np.count_nonzero(~np.isnan(part)))
            new = np.flatnonzero(np.isfinite(part))
            r = np.searchsorted(offset, new, side="right") - 1 + lo     # the pair of ab each new one joins
            found = (v1[r], w1[r], w2[first[r] + new - offset[r - lo]])
            held = tuple(np.concatenate([h, f]) for h, f in zip(held, found))
            score = np.concatenate([score, part[new]])
            best = stable_order(score)[:FIELD_KEEP]
            held, score = tuple(h[best] for h in held), score[best]
            lo = hi
    R, t = triangle_poses(P, *held, data_frame, x[a])
    return R, t, score, tried


def _agree(R, surface, normals, sd) -> np.ndarray:
    """Whether each pose ``R (h, 3, 3)``'s model normals ``surface (h, n, 3)`` (at the posed contacts)
    agree with the contacts' ``normals (n, 3)`` ``(h,)``: the sum over the contacts with a stated
    uncertainty of their squared angles to the model's normals in units of it is a chi-square of two
    degrees of freedom a contact when the pose is the truth; a pose agrees when that sum lies within
    the quantile :data:`SIGMAS` standard normal deviations out (the fit test's allowance).  A normal
    without its uncertainty tests nothing."""
    from scipy.stats import chi2, norm

    test = np.isfinite(sd) & np.isfinite(normals[:, 0])
    if not test.any():
        return np.ones(len(R), dtype=bool)
    turned = np.einsum("hij,kj->hki", R, normals[test])
    total = np.sum((_angle(turned, surface[:, test]) / sd[test]) ** 2, axis=1)
    return total <= chi2.isf(norm.sf(SIGMAS), 2 * int(test.sum()))


def _kept(model, R, t, score, x, normals, sd) -> np.ndarray:
    """The indices of the :data:`KEEP` poses ``R (h, 3, 3), t (h, 3)`` refined on exact distances: those
    whose normals agree with the contacts' (:func:`_agree`, at the model's normals where each pose puts
    the contacts ``x``) first, by the field's ``score``, then the others by it.  The test that accepts a
    pose decides which poses the exact steps are spent on: a few contacts fit many poses by their
    distances alone, and the best by distance need not be the ones their normals allow."""
    order = stable_order(score)
    surface = model.planes(transform(R[order], t[order], x))[1]
    agree = _agree(R[order], surface, normals, sd)
    return np.concatenate([order[agree], order[~agree]])[:KEEP]


def contact_stage(held, indices, touch, limit: float, fit: float) -> list[Registration]:
    """A runner's stage: each model of ``indices`` posed on the contacts of ``touch`` (a
    :class:`~tactrec.features.Touch` of a ``contacts`` touch; see the module text).  The triangles are
    posed in turn until one's best pose agreeing with the normals is a fit: its mean distance within
    ``limit`` (data units, the touch's :func:`~tactrec.probability.plausible_fit`); ``fit``: its fit
    limit (data units, :func:`tangent_points`)."""
    from ..registration.solver import Criteria, solve
    from ..units import conversion
    from .kernels import field_refine

    out = []
    for i in indices:
        model = held.entries[i].model
        name = held.entries[i].name
        if model.kind != "mesh":
            out.append(Registration(name, np.inf, outcome=Outcome.REJECTED,
                                    reason="contacts are posed on meshes only"))
            continue
        scale = float(conversion(touch.data.units, getattr(model, "units", None)))
        c = touch.data.contacts
        x = c.points * scale
        xa = np.ascontiguousarray(tangent_points(x, c.normals, c.normal_sd, fit * scale))
        limit_model = limit * scale
        P, N, reach = _places(model)
        tol = 2.0 * reach + SIGMAS * np.sqrt(2.0) * touch.noise * scale
        field, tried, found = model.distance_field, 0, None
        for tri in triangles(x, TRIANGLES):
            R, t, score, posed = _triangle_screen(field, P, N, x, xa, c.normals, c.normal_sd, tri, tol)
            tried += posed
            if not len(R):
                continue
            R, t, score = field_refine(*field.args(), R, t, xa, FIELD_STEPS)
            best = _kept(model, R, t, score, x, c.normals, c.normal_sd)
            refined = solve(model, R[best], t[best], xa, Criteria(STEPS))
            distance, surface = model.planes(transform(refined.R, refined.t, x))           # the contacts' own
            error = np.abs(distance).mean(axis=1)
            agree = _agree(refined.R, surface, c.normals, c.normal_sd)
            if agree.any():
                least = float(error[agree].min())
                if found is None or least < found[3]:
                    found = refined, error, agree, least
                if least <= limit_model:
                    break                                       # a fit: no other triangle can do better
        if found is None:
            out.append(Registration(name, np.inf, outcome=Outcome.REJECTED,
                                    reason="no places as far apart" if not tried else
                                    "no pose agrees with the contacts' normals"))
            continue
        refined, error, agree, _ = found
        order = sorted(np.flatnonzero(agree), key=lambda h: (error[h], h))
        h = order[0]
        alternatives = np.concatenate([refined.R[order[1:]], refined.t[order[1:], :, None]], axis=2)
        out.append(Registration(name, float(error[h]), location=rotate(refined.R[h], x[0]) + refined.t[h],
                                rotation=refined.R[h], translation=refined.t[h], scale=scale, candidates=int(tried),
                                alternatives=alternatives))
    return out
