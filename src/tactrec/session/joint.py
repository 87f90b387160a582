"""Steps 2-4 and 6 of a session's add (:mod:`.core`): every model's joint pose on the touches, which
touches are consistent with it, which have slipped, and the session's result.

:class:`JointFit` holds these steps for :class:`~.core.Session`, which it is a part of: it reads the
session's records, recognizer, this add's searches and fits.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..linalg import clearly_less
from . import family as _family
from .fit import fit_stage
from .record import fits
from .result import Hypothesis, SessionResult

__all__ = ["JointFit"]


class JointFit:
    """The joint fit of :class:`~.core.Session` (steps 2-4 and 6 of its module text)."""

    def _candidates(self, name: str, start: Hypothesis | None = None,
                    searches=None) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Model ``name``'s candidate poses ``(R, t, scale)``: ``start``'s pose (default: its joint pose
        so far, with its family where computed), then the poses of ``searches`` (default: this add's)."""
        poses = []
        h = self._joint.get(name) if start is None else start
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

    def consistent(self, name: str, per_touch: np.ndarray) -> np.ndarray:
        """Which touches are consistent (module text, step 3) with poses of model ``name`` whose
        per-touch mean distances (data units) are ``per_touch (h, N)``: ``(h, N)`` bool, by the one
        fit test against each touch's own fit on the model."""
        return fits(per_touch, self._reference(name)[None], self._points(range(len(self.records)))[None])

    def _fit_models(self, use: np.ndarray, fresh=None) -> dict[str, Hypothesis]:
        """Every model's joint pose on the touches ``use (N,)`` (bool): its candidate poses scored on
        them, the best :data:`~.fit.REFINED` refined on their points
        (:func:`~.fit.fit_stage`, in the recognizer's workers), the best kept.  A model
        already fitted on these touches in this add is fitted again only from that fit and the poses
        of ``fresh`` (the search just made): the other candidates lost to it on the same points."""
        done = self._fits.setdefault(use.tobytes(), {})
        entries, items = [], []
        for i, e in enumerate(self.recognizer.models):
            if e.name in done:
                if fresh is None or not any(r.model == e.name and r.ok for r in fresh.ranking):
                    continue
                poses = self._candidates(e.name, done[e.name], [fresh])
            else:
                poses = self._candidates(e.name)
            if poses:
                entries.append((i, e))
                items.append((np.stack([p[0] for p in poses]), np.stack([p[1] for p in poses]), poses[0][2]))
        weight = np.array([len(f.points) for f in self.features]) * use
        tips = self.tips if np.any(self.tips) else None
        fitted = self.recognizer.runner.map(fit_stage, [i for i, _ in entries], [f.points for f in self.features],
                                            weight, tips, items=items)
        for (_, e), (_, _, scale), poses in zip(entries, items, fitted):
            best = None
            for R, t, per in poses:
                err = float((per * weight).sum() / max(weight.sum(), 1))
                if best is None or clearly_less(err, best.error):
                    best = Hypothesis(e.name, R, t, scale, err, per,
                                      tuple(bool(c) for c in self.consistent(e.name, per[None])[0]))
            done[e.name] = best
        return dict(done)

    def family(self, name: str) -> np.ndarray:
        """Model ``name``'s pose and the poses along the motions its touches leave free, ``(p, 3, 4)``
        (:func:`.family.free_poses`; computed when asked, for the models :meth:`next` weighs)."""
        h = self._joint[name]
        if h.poses is None:
            model = next(e.model for e in self.recognizer.models if e.name == name)
            kept = self.kept()
            use = np.isin(np.arange(len(self.records)), kept)
            x = np.concatenate([self.records[i].points for i in kept]) * h.scale
            h = dataclasses.replace(h, poses=_family.free_poses(self, model, h, use, x))
            self._joint[name] = h
        return h.poses

    def _joint_fit(self, fresh=None) -> SessionResult:
        """Steps 2-4 and 6, after the search ``fresh`` of step 5 (None: after the touch's own)."""
        return self._timed("joint", self._joint_fit_untimed, fresh)

    def _joint_fit_untimed(self, fresh=None) -> SessionResult:
        n = len(self.records)
        every = np.ones(n, dtype=bool)
        found = self._fit_models(every, fresh)
        # a touch has slipped when no pose that fits most touches fits it; without such a pose
        # the session cannot tell which touch is the odd one out
        majority = [h for h in found.values() if 2 * sum(h.consistent) > n]
        slipped = tuple(i for i in range(n) if not any(h.consistent[i] for h in majority)) if majority else ()
        keep = [i for i in range(n) if i not in slipped]
        if slipped:
            use = np.isin(np.arange(n), keep)
            found = self._fit_models(use, fresh)
        self._joint = found
        ranked = sorted(found.values(), key=lambda h: (h.error, h.model))
        rejected = {e.name: "no pose from any touch" for e in self.recognizer.models if e.name not in found}
        return SessionResult(ranked, self._evidence(ranked, keep), slipped, n, rejected, 0.0,
                             self.features[-1].geometry, unknown_prior=self.recognizer.unknown_prior,
                             missed=len(self.misses), outliers=tuple(f.outliers for f in self.features),
                             chance=self.recognizer.chance)


