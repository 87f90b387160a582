"""Steps 2-4 and 6 of a session's add (:mod:`.core`): every model's joint pose on the touches, which
touches are consistent with it, which have slipped, and the session's result.

:class:`JointFit` is a collaborator of one add (:class:`~.add.Add`): it is given the touches, the
lines that met nothing, the joint poses so far and the add's recognitions, keeps the fits it makes
over each set of touches for the rest of the add, and is dropped with it.
"""

from __future__ import annotations

import numpy as np

from ..features import Touch
from ..io.touch import TactileData
from ..linalg import clearly_less
from ..missed import line_step, miss_excess
from ..probability import evidence, fit_limit, residuals, resolution
from .fit import fit_stage, joint_model
from .result import Hypothesis, SessionResult
from .touches import Touches

__all__ = ["JointFit", "session_evidence"]


def session_evidence(recognizer, touches: Touches, misses, ranked, keep):
    """The :class:`~tactrec.probability.Evidence` of the hypotheses ``ranked`` over the touches
    ``keep`` (indices) and the lines that met nothing, ``misses`` (None without a hypothesis or a
    touch)."""
    if not ranked or not keep:
        return None
    by_name = {e.name: e.model for e in recognizer.models}
    features, records = touches.features, touches.records
    # the touches of single contacts are one touch, as they are one search (:meth:`.add.Add._pooled`): after the others
    contacts = [i for i in keep if records[i].world.contacts is not None]
    order = [i for i in keep if i not in contacts] + contacts
    x = np.concatenate([records[i].points for i in order])
    curves = [len(c) for i in order for c in features[i].curves]
    points = [records[i].points for i in order]
    signed = [residuals(joint_model(by_name[h.model], points, touches.tips[order], h.scale), h.rotation,
                        h.translation, x, h.scale) for h in ranked]
    lines = None
    if misses:
        step = line_step(0.5 * float(np.median([records[i].world.spacing for i in keep])),
                         max(line.length for line in misses))
        lines = miss_excess(by_name, ranked, misses, step=step, limit=touches.limit(keep))
    floor = touches.floor
    parts = [features[i] for i in order if i not in contacts]
    sizes = [len(f.curves) for f in parts]
    if contacts:
        first = records[contacts[0]].world
        parts.append(Touch.from_data(TactileData.from_contacts(touches.joined_contacts(contacts), units=first.units,
                                                               source=first.source)))
        sizes.append(sum(len(features[i].curves) for i in contacts))
    kinds = {f.data.kind for f in parts}
    return evidence([h.model for h in ranked], signed, curves, float(np.median([f.noise for f in features])),
                    limits=[fit_limit(f, floor) for f in parts], touches=sizes, misses=lines,
                    resolution=min(resolution(f, floor) for f in parts), radii=[f.radius for f in parts],
                    kind=kinds.pop() if len(kinds) == 1 else "mixed")


class JointFit:
    """Steps 2-4 and 6 over ``touches`` (see the module text): ``joint``, every model's joint pose so
    far (updated by each fit), ``searches`` the add's recognitions (where new candidate poses come
    from; the add appends to it)."""

    def __init__(self, recognizer, touches: Touches, misses, joint: dict, searches: list):
        self.recognizer, self.touches, self.misses = recognizer, touches, tuple(misses)
        self.joint = dict(joint)
        self.searches = searches
        self.fits: dict[bytes, dict[str, Hypothesis]] = {}       # this add's fits, per set of touches used

    def candidates(self, name: str, start: Hypothesis | None = None,
                   searches=None) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Model ``name``'s candidate poses ``(R, t, scale)``: ``start``'s pose (default: its joint pose
        so far, with its family where computed), then the poses of ``searches`` (default: the add's)."""
        poses = []
        h = self.joint.get(name) if start is None else start
        if h is not None:
            family = h.poses if h.poses is not None else [np.concatenate([h.rotation, h.translation[:, None]], 1)]
            poses += [(pose[:, :3], pose[:, 3], h.scale) for pose in family]
        for rec in self.searches if searches is None else searches:
            r = next((r for r in rec.ranking if r.model == name and r.ok), None)
            if r is not None:
                poses.append((r.rotation, r.translation, r.scale))
                for alt in (() if r.alternatives is None else r.alternatives):
                    poses.append((alt[:, :3], alt[:, 3], r.scale))
        return poses

    def fit_models(self, use: np.ndarray, fresh=None) -> dict[str, Hypothesis]:
        """Every model's joint pose on the touches ``use (N,)`` (bool): its candidate poses scored on
        them, the best :data:`~.fit.REFINED` refined on their points
        (:func:`~.fit.fit_stage`, in the recognizer's workers), the best kept.  A model
        already fitted on these touches in this add is fitted again only from that fit and the poses
        of ``fresh`` (the search just made): the other candidates lost to it on the same points."""
        done = self.fits.setdefault(use.tobytes(), {})
        entries, items = [], []
        for i, e in enumerate(self.recognizer.models):
            if e.name in done:
                if fresh is None or not any(r.model == e.name and r.ok for r in fresh.ranking):
                    continue
                poses = self.candidates(e.name, done[e.name], [fresh])
            else:
                poses = self.candidates(e.name)
            if poses:
                entries.append((i, e))
                items.append((np.stack([p[0] for p in poses]), np.stack([p[1] for p in poses]), poses[0][2]))
        features = self.touches.features
        weight = np.array([len(f.points) for f in features]) * use
        tips = self.touches.tips if np.any(self.touches.tips) else None
        fitted = self.recognizer.runner.map(fit_stage, [i for i, _ in entries], [f.points for f in features],
                                            weight, tips, items=items)
        for (_, e), (_, _, scale), poses in zip(entries, items, fitted):
            best = None
            for R, t, per in poses:
                err = float((per * weight).sum() / max(weight.sum(), 1))
                if best is None or clearly_less(err, best.error):
                    best = Hypothesis(e.name, R, t, scale, err, per,
                                      tuple(bool(c) for c in self.touches.consistent(e.name, per[None])[0]))
            done[e.name] = best
        return dict(done)

    def __call__(self, fresh=None) -> SessionResult:
        """Steps 2-4 and 6, after the search ``fresh`` of step 5 (None: after the touch's own)."""
        n = len(self.touches)
        every = np.ones(n, dtype=bool)
        found = self.fit_models(every, fresh)
        # a touch has slipped when no pose that fits most touches fits it; without such a pose
        # the session cannot tell which touch is the odd one out
        majority = [h for h in found.values() if 2 * sum(h.consistent) > n]
        slipped = tuple(i for i in range(n) if not any(h.consistent[i] for h in majority)) if majority else ()
        keep = [i for i in range(n) if i not in slipped]
        if slipped:
            use = np.isin(np.arange(n), keep)
            found = self.fit_models(use, fresh)
        self.joint = found
        ranked = sorted(found.values(), key=lambda h: (h.error, h.model))
        rejected = {e.name: "no pose from any touch" for e in self.recognizer.models if e.name not in found}
        features = self.touches.features
        return SessionResult(ranked, session_evidence(self.recognizer, self.touches, self.misses, ranked, keep),
                             slipped, n, rejected, 0.0, features[-1].geometry,
                             unknown_prior=self.recognizer.unknown_prior, missed=len(self.misses),
                             outliers=tuple(f.outliers for f in features), chance=self.recognizer.chance)
