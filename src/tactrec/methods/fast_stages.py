"""Method ``fast``'s stages, run per model in worker processes (see :mod:`tactrec.methods.fast`).

Step 1, the cheap stage (:func:`cheap_stage`); step 3, refinement (:func:`refine_stage`); the final polish
(:func:`polish_stage`, which also refits a search's registrations on a touch of nearly the same
points); and closed-form surfaces (:func:`closed_form_stage`).

A touch with a round tip follows the one rule of :mod:`tactrec.tip`: the places, the field screen,
its field steps and local grid take the mesh and the touch as the search sees them
(:meth:`~tactrec.features.Touch.searched`: the centres on the mesh offset by the tip); every exact
step and error is measured from the centres against the model offset by the tip
(:meth:`~tactrec.features.Touch.exact`).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from ..engine import LOOKUP_COST
from ..linalg import stable_order
from ..registration import closedform_fast, mesh_fast
from ..registration.result import Outcome, Registration
from ..registration.solver import Criteria, mean_distance, solve
from .common import best_of_orientations, in_model_units

if TYPE_CHECKING:
    from .fast import FastConfig

__all__ = ["tier_span", "field_stages", "Poses", "Cheap", "Found"]


@dataclasses.dataclass(frozen=True)
class Poses:
    """Poses of one model, best first: ``R (k, 3, 3), t (k, 3)`` (data onto model), their cheap scores
    ``score (k,)`` (data units) and the side of the normal each was posed from, ``sign (k,)``."""

    R: np.ndarray
    t: np.ndarray
    score: np.ndarray
    sign: np.ndarray

    def within(self, bound: float) -> "Poses":
        """The poses whose score is at most ``bound``."""
        keep = self.score <= bound
        return Poses(self.R[keep], self.t[keep], self.score[keep], self.sign[keep])


@dataclasses.dataclass(frozen=True)
class Cheap:
    """Step 1 of a tier on one model (:func:`cheap_stage`): its best poses (``outcome`` fitted), why it is
    ruled out (rejected, ``reason``), or nothing new to pose (not searched: every place of a field
    tier was screened by earlier tiers); the closest-point queries and the places it tried."""

    outcome: Outcome
    queries: int
    places: int = 0
    poses: Poses | None = None
    reason: str = ""


@dataclasses.dataclass(frozen=True)
class Found:
    """A stage's registration of one model and the closest-point queries it made."""

    registration: Registration
    queries: int

def offset_of(model) -> float:
    """The radius a mesh as the search sees it is offset by (0: the mesh itself): part of a cache key,
    as a touch's centres searched with a tip have the key of the same points without one."""
    from ..surfaces.mesh_offset import OffsetMesh

    return model.radius if isinstance(model, OffsetMesh) else 0.0


def touch_gaps(held, index: int, model, touch, g, sign: int):
    """Each vertex's curvature gap to ``touch`` and the touch's fit
    (:func:`~tactrec.registration.mesh_fast.curvature_gaps`) on ``model`` (the mesh of entry ``index``
    as the search sees it: :meth:`~tactrec.features.Touch.searched`), for its estimate ``g`` on side
    ``sign``, computed once per touch."""
    key = (touch.key, index, offset_of(model), sign)
    if key not in held.cache:
        if len(held.cache) > 8 * len(held.entries) + 8:           # another touch: forget the last one's
            held.cache.clear()
        held.cache[key] = mesh_fast.curvature_gaps(model, g, touch.points)
    return held.cache[key]


def ranked_places(held, index: int, model, touch, g, sign: int, config: FastConfig, kind: str,
            count: int | None) -> np.ndarray:
    """The first ``count`` places of ``model`` (None: all) in order of curvature gap (:func:`touch_gaps`),
    maybe a few more: of ``kind`` ``"every"``, every vertex; ``"cells"``, the best vertex of each
    grid cell ``radius / spread`` across (:func:`~tactrec.registration.mesh_fast.first_per_cell`);
    ``"screen"``, the field screen's places (:func:`tactrec.engine.screen.screen_places`);
    ``"folded"``, the folded ones alone (which the order's start cannot tell: a cell is folded by
    any of its vertices).  Kept for the touch, and extended when a later tier takes more."""
    key = (touch.key, index, offset_of(model), sign, kind)
    found, complete = held.cache.get(key, (None, False))
    if found is None or not (complete or (count is not None and len(found) >= count)):
        gaps, _ = touch_gaps(held, index, model, touch, g, sign)
        if kind == "every":
            def thin(order):
                return order
        elif kind == "cells":
            def thin(order):
                return mesh_fast.first_per_cell(model, order, touch.radius / config.spread)
        else:
            from ..engine.screen import screen_places

            def thin(order):
                return screen_places(model, order, touch.radius, step=config.screen_step, angle=config.tilt_step,
                                     folded=kind == "folded")
        if kind == "folded":
            count = None
        found = mesh_fast.leading_places(gaps, count, thin)
        held.cache[key] = (found, count is None or len(found) < count)
    return found


def tier_span(tiers, k: int) -> tuple[int, int | None]:
    """Which of the ranked places tier ``k`` adds: those past the deepest earlier tier of the same kind."""
    tier = tiers[k]
    start = max((t.places or 0 for t in tiers[:k]
                 if (t.rotations, t.tilt, t.folded, t.indexed) == (tier.rotations, tier.tilt, tier.folded, tier.indexed)),
                default=0)
    return start, tier.places


def field_stages(config: FastConfig, tier) -> tuple:
    """A field tier's screen stages: ``config.screen_stages``, or in a tilted tier two stages turning
    the data every ``tilt_step`` degrees and then twice as finely, matching the tilts' grid."""
    if tier.tilt <= 0:
        return config.screen_stages
    turns = max(1, int(round(360.0 / config.tilt_step)))
    return (turns, *config.screen_stages[0][1:]), (2 * turns, *config.screen_stages[-1][1:])


def field_poses(model, s, g, sign: int, spots: np.ndarray, fit, tier, config: FastConfig, context, exact, x,
                keep: int | None = None):
    """A field tier's hypotheses at the places ``spots``: screened on the field with the data's normals
    (or, in a tilted tier, with normals tilted out to ``tier.tilt`` degrees, then each of the best
    few set on a dense local grid: :func:`tactrec.engine.screen.local_screen`), the best
    ``screen_keep`` (or ``keep``) refined on the field and the best ``2 refine`` of those taking one exact step.
    ``model`` and ``s`` are the mesh and the touch as the search sees them
    (:meth:`~tactrec.features.Touch.searched`), ``g`` the touch's estimate on the side tried;
    ``context`` the other touches' points the screen scores; ``exact`` what the exact step measures
    the touch's points ``x`` against (:meth:`~tactrec.features.Touch.exact`).  Returns ``R, t,
    score, queries, hypotheses screened``."""
    from ..engine.kernels import field_refine            # numba: only once a search needs it
    from ..engine.screen import DISTINCT, data_normals, local_screen, screen, tilted_normals

    stages = field_stages(config, tier)
    if tier.tilt > 0:        # one screen over every tilted normal
        normals = [(np.stack(tilted_normals(fit[2], g.tangents[0], cone=tier.tilt, step=config.tilt_step)),
                    "fitted")]
    else:
        normals = data_normals(g, fit[2], distinct=DISTINCT, fine=s.fine_normal(sign))
    field = model.distance_field
    x3, poses, lookups, q, tried = s.joint_subset(3 * config.coarse_points), [], 0, 0, 0
    for dn, kind in normals:
        onto = model.fine_curvatures.normal[spots] if kind == "fitted" else model.vertex_normals[spots]
        found = screen(model, g, spots, onto, s.curves, dn,
                       stages=stages, keep=config.screen_keep if keep is None else keep, extra=context)
        R, tr, grid = field_refine(*field.args(), found.R, found.t, x3, config.field_steps)
        lookups += found.lookups + len(R) * len(x3) * (config.field_steps + 1)
        tried += len(found.owner)
        best = stable_order(grid)[:2 * config.refine]
        poses.append(solve(exact, R[best], tr[best], x, Criteria(1, tolerance=config.tolerance, predict=True)))
        q += poses[-1].queries
    R, tr, score = (np.concatenate([getattr(p, k) for p in poses]) for k in ("R", "t", "error"))
    if tier.tilt > 0:
        seeds = stable_order(score)[:config.refine]
        R, tr, _, n = local_screen(model, R[seeds], tr[seeds], s.joint_subset(config.coarse_points), g.contact,
                                   angle=0.6 * config.tilt_step,
                                   shift=0.75 * config.screen_step * s.radius)
        lookups += n
        R, tr, score, q2 = solve(exact, R, tr, x, Criteria(1, tolerance=config.tolerance, predict=True))
        q += q2
    return R, tr, score, int(lookups * LOOKUP_COST) + q, tried


#: a model ruled out for a touch that does not fit on it (:func:`oversized`)
OVERSIZED = Cheap(Outcome.REJECTED, 0, reason="the touch is larger than the model")


def oversized(t, model) -> bool:
    """Whether the touch ``t`` (in ``model``'s units) reaches farther than the model is across."""
    return bool(t.radius > model.size or t.joint_reach > model.size)


def fitted(poses: list[tuple], config: FastConfig, t, queries: int, tried: int) -> Cheap:
    """Step 1's outcome on a model from its hypotheses ``poses`` (``(R, t, score, sign)`` each, model
    units): its best ``refine`` poses and their cheap scores in the data's units."""
    R, tr, score, signs = (np.concatenate([p[i] for p in poses]) for i in range(4))
    keep = stable_order(score)[:config.refine]
    return Cheap(Outcome.FITTED, int(queries), tried, Poses(R[keep], tr[keep], score[keep] / t.scale, signs[keep]))


def cheap_stage(held, indices, touch, config: FastConfig, k: int) -> list[Cheap]:
    """Step 1 of tier ``k`` on each mesh model: its best ``refine`` poses and their cheap scores."""
    tier = config.tiers[k]
    out = []
    for index in indices:
        model = held.entries[index].model
        t = in_model_units(touch, model)
        if oversized(t, model):
            out.append(OVERSIZED)
            continue
        x, screened = t.joint_subset(config.coarse_points), t.screen_subset(config.coarse_points)
        exact, exact_screened = t.exact(model, config.coarse_points), t.exact(model, config.coarse_points, screen=True)
        poses, queries, tried = [], 0, 0
        for sign, _ in t.sides:
            seen, s, g = t.searched(model, sign)                 # (a) of tactrec.tip
            _, fit = touch_gaps(held, index, seen, s, g, sign)
            start, stop = tier_span(config.tiers, k)
            if tier.rotations == "field":
                # a folded tier reaches here only for a touch whose normals disagree (FastMethod.search)
                kind = "folded" if tier.folded else "screen"
                spots = ranked_places(held, index, seen, s, g, sign, config, kind, stop)[start:stop]
                if len(spots) == 0:
                    continue
                context_middles = s.screen_subset(config.coarse_points)[len(s.subset(config.coarse_points)):] \
                    if t.context else None
                R, tr, score, q, n = field_poses(seen, s, g, sign, spots, fit, tier, config, context_middles, exact, x)
                tried, queries = tried + n, queries + q
                poses.append((R, tr, score, np.full(len(R), sign)))
                continue
            # a tier of every place (the exhaustive reference) takes every vertex, not one a cell
            chosen = ranked_places(held, index, seen, s, g, sign, config, "every" if stop is None else "cells", stop)
            for lo in range(start, len(chosen) if stop is None else min(stop, len(chosen)), 1000):
                part = chosen[lo:min(lo + 1000, len(chosen) if stop is None else stop)]
                tried += len(part)
                R, tr, owner = mesh_fast.frame_poses(seen, g, part, fit, rotations=tier.rotations,
                                                     umbilic=config.umbilic / s.radius, tilt=tier.tilt)
                steps = config.cheap_steps
                kept = max(config.screen, len(R) // 8)
                if tier.places is not None and len(R) > kept and steps > 1:
                    R, tr, first, q = solve(exact_screened, R, tr, screened, Criteria(1, predict=True))
                    keep = stable_order(first)[:kept]
                    R, tr, owner, steps, queries = R[keep], tr[keep], owner[keep], steps - 1, queries + q
                R, tr, score, q = solve(exact, R, tr, x, Criteria(steps, tolerance=config.tolerance, predict=True,
                                                                history=config.history))
                queries += q
                order = np.lexsort((stable_order(score).argsort(), owner))          # each place's best rotation
                best = order[np.r_[True, owner[order][1:] != owner[order][:-1]]]
                poses.append((R[best], tr[best], score[best], np.full(len(best), sign)))
        if not poses and tier.rotations == "field":          # every place screened by earlier tiers
            out.append(Cheap(Outcome.NOT_SEARCHED, int(queries), tried))
            continue
        if not poses:
            out.append(Cheap(Outcome.REJECTED, int(queries), tried, reason="no place to start from"))
            continue
        out.append(fitted(poses, config, t, queries, tried))
    return out


def mesh_registration(model, touch, R: np.ndarray, t: np.ndarray, error: float, sign: int) -> Registration:
    """The registration of pose ``R (3, 3), t (3,)`` on a mesh, with the normal of sign ``sign`` (its
    spread measured against the model offset by the touch's tip)."""
    return mesh_fast.registration(touch.exact(model), touch.oriented(sign), R, t, error, candidates=0, sign=sign, scale=touch.scale,
                                  x=touch.joint_points)


def refine_stage(held, indices, touch, config: FastConfig, chosen: list[Poses]) -> list[Found]:
    """Step 3 on each model: the chosen poses refined on exact distances; the best as a registration."""
    out = []
    for index, poses in zip(indices, chosen):
        model = held.entries[index].model
        t = in_model_units(touch, model)
        R, tr, error, q1 = solve(t.exact(model, 3 * config.coarse_points), poses.R, poses.t,
                                 t.joint_subset(3 * config.coarse_points),
                                 Criteria(config.iterations, tolerance=config.tolerance, history=config.history))
        order = stable_order(error)
        b = order[0]
        others = np.concatenate([R[order], tr[order][:, :, None]], axis=2)                 # (k, 3, 4), best first
        R, tr, error, q2 = solve(t.exact(model), R[b:b + 1], tr[b:b + 1], t.joint_points,
                                 Criteria(2, tolerance=config.tolerance, history=config.history))
        found = mesh_registration(model, t, R[0], tr[0], error[0], int(poses.sign[b]))
        out.append(Found(dataclasses.replace(found, alternatives=others), q1 + q2))
    return out


def polish_stage(held, indices, touch, config: FastConfig, fresh: bool,
                 registrations: list[Registration]) -> list[Found]:
    """The registrations refined further on all points: ``polish_iterations`` exact steps from their
    poses, kept only where they lower the error.  With ``fresh``, they come from a search of nearly
    the same points (the same touch, a few of its points set aside or taken back:
    :meth:`~tactrec.methods.fast.FastMethod.refit`), and their errors are this touch's, whether or not
    the steps lower them."""
    out = []
    for index, r in zip(indices, registrations):
        model = held.entries[index].model
        t = in_model_units(touch, model)
        exact = t.exact(model)
        if model.kind == "mesh":
            R, tr, error, q = solve(exact, r.rotation[None], r.translation[None], t.joint_points,
                                    Criteria(config.polish_iterations, tolerance=config.tolerance,
                                             history=config.history))
            better = dataclasses.replace(mesh_registration(model, t, R[0], tr[0], error[0], r.normal_sign),
                                         alternatives=r.alternatives) if fresh or error[0] < r.error else r
        else:
            start = dataclasses.replace(r, error=float(mean_distance(exact, r.rotation[None], r.translation[None],
                                                                     t.joint_points)[0])) if fresh else r
            better = dataclasses.replace(closedform_fast.polish(model, start, t.oriented(r.normal_sign),
                                                                t.joint_points, exact=exact),
                                         normal_sign=r.normal_sign, scale=r.scale)
            q = (config.polish_iterations + int(fresh)) * len(t.joint_points)
        if fresh:
            better = dataclasses.replace(better, alternatives=r.alternatives, candidates=r.candidates)
        out.append(Found(better, q))
    return out


def hop_cost(config: FastConfig, curves: int, points: int) -> int:
    """The closest-point queries of :func:`hop_stage` on one model: ``hop_seeds`` grids of
    ``hop_steps**6`` poses, each two steps on ``coarse_points`` points a curve; the best ``2 refine``
    ``iterations`` steps on three times those points, and the best of them as many on all ``points``."""
    grid = config.hop_seeds * config.hop_steps ** 6
    refine = 2 * config.refine * 3 * config.coarse_points * curves
    return int(2 * grid * config.coarse_points * curves + config.iterations * (refine + points))


def hop_stage(held, indices, touch, config: FastConfig, items: list[tuple[Registration, float]]) -> list[Found]:
    """The registrations ``items`` beyond the fit limit, each with its grid's span, searched again
    about its pose and its best alternatives (``hop_seeds`` in all): a grid of turns and shifts about
    the contact's image (:func:`tactrec.engine.screen.local_poses`, ``hop_steps`` values of each of
    the six, ``span`` x ``hop_angle`` degrees and ``span`` x ``hop_shift`` x the touch's radius
    out), every pose two exact steps on a few points a curve, the best ``2 refine`` then
    ``iterations`` steps on three times as many (as a tier's refinement), and the best of those as
    many on all points; kept where the error falls.
    The grid's step is the exact steps' basin (a start a degree or two and a tenth of a millimetre
    off reaches the fit; from farther on a scan's facets the steps settle on a nearby pose that
    fits a few times worse), so one of its poses lies in the true pose's basin when the search
    ended within a grid's span of it."""
    from ..engine.screen import local_poses

    out = []
    for index, (r, span) in zip(indices, items):
        model = held.entries[index].model
        t = in_model_units(touch, model)
        seeds = [np.concatenate([r.rotation, r.translation[:, None]], axis=1)]
        if r.alternatives is not None:
            seeds += [a for a in r.alternatives[1:config.hop_seeds]]
        seeds = np.stack(seeds[:config.hop_seeds])
        R, tr = local_poses(seeds[:, :, :3], seeds[:, :, 3], t.geometry.contact, angle=span * config.hop_angle,
                            shift=span * config.hop_shift * t.radius, steps=config.hop_steps)
        R, tr, first, q1 = solve(t.exact(model, config.coarse_points), R, tr, t.joint_subset(config.coarse_points),
                                 Criteria(2, tolerance=config.tolerance, predict=True))
        best = stable_order(first)[:2 * config.refine]
        steps = Criteria(config.iterations, tolerance=config.tolerance, history=config.history)
        R, tr, error, q2 = solve(t.exact(model, 3 * config.coarse_points), R[best], tr[best],
                                 t.joint_subset(3 * config.coarse_points), steps)
        b = int(stable_order(error)[0])
        R, tr, error, q3 = solve(t.exact(model), R[b:b + 1], tr[b:b + 1], t.joint_points, steps)
        better = r
        if error[0] < r.error:
            better = dataclasses.replace(mesh_registration(model, t, R[0], tr[0], error[0], r.normal_sign),
                                         alternatives=r.alternatives, candidates=r.candidates)
        out.append(Found(better, q1 + q2 + q3))
    return out


def closed_form_stage(held, indices, touch, config: FastConfig) -> list[Found]:
    """Closed-form surfaces: the nearest table rows, refined in six degrees of freedom."""
    out = []
    for index in indices:
        entry = held.entries[index]
        t = in_model_units(touch, entry.model)
        r = best_of_orientations(lambda g, sign: closedform_fast.register(
            entry.model, entry.table, g, t.joint_points, candidates=config.candidates, exact=t.exact(entry.model),
            surface=t.on_surface(sign).joint_points), t, entry.model.name)
        out.append(Found(r, config.candidates * 12 * len(t.joint_points)))
    return out
