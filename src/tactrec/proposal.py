"""Where to touch next: the touch that best separates a session's leading hypotheses.

The hypotheses are the session's models, each at its joint pose
(:mod:`tactrec.session`), with their probabilities.  The *leading* ones are
the most probable, until they hold :data:`MASS` of the probability (at most
:data:`LEADING`).  With one left there is nothing to separate and nothing is
proposed.

Candidates.  Places on the leading hypotheses' surfaces (random sites of each
model, carried into the world by its pose) that every leading hypothesis puts
on the object's surface (within ``tolerance`` of its model, under one of its
poses), that lie within ``radius`` of an earlier touch's contact, and where
every pose's surface takes the whole touch: places the sensor can reach and
every hypothesis agrees it will meet and can trace.

Gain.  At a candidate, each hypothesis predicts the touch the sensor would
record: three curves through the place, in the same world directions, as the
session's touches are (their points per curve and spacing), noise-free.  If
hypothesis ``i`` is true, hypothesis ``j`` would fit that touch at mean
distance ``d_ij``: ``i``'s predicted points measured against ``j``'s surface
once ``j``'s pose is refitted to them and the earlier touches together (a
pose the earlier touches leave free, along a cylinder or over a flat patch,
slides to absorb what it can).  It would be told apart from ``i`` by
``z_ij = d_ij / SE``, ``SE`` the
standard error of a fit under the session's noise (:mod:`tactrec.probability`).
The posterior after the touch is then ``p_j exp(-z_ij^2 / 2)`` normalised,
and the expected gain is the entropy now less its expectation after, in bits.
The candidate of largest gain is proposed.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .probability import fit_standard_error, noise_fit
from .simulation import simulate_world_touch

__all__ = ["Proposal", "propose", "MASS", "LEADING"]

#: the leading hypotheses hold this much probability, and are at most this many
MASS, LEADING = 0.99, 4


@dataclasses.dataclass(frozen=True)
class Proposal:
    """A proposed touch, world frame (``contact`` None when nothing is left to separate).

    Attributes
    ----------
    contact, normal : (3,) float or None
        Where the sensor should meet the surface, and the outward normal there (approach along
        ``-normal``), under the most probable hypothesis.
    directions : (3, 3) float or None
        Tangent directions of the curves to trace.
    gain : float
        Expected information gain, bits.
    hypotheses : list of (str, float)
        The leading hypotheses and their probabilities.
    reason : str
        Why nothing is proposed, when nothing is.
    """

    contact: np.ndarray | None
    normal: np.ndarray | None
    directions: np.ndarray | None
    gain: float
    hypotheses: list
    reason: str = ""

    def to_json(self) -> dict:
        out = {"hypotheses": [{"model": m, "probability": float(p)} for m, p in self.hypotheses]}
        if self.contact is None:
            out.update(contact=None, gain=0.0, reason=self.reason)
            return out
        out.update(contact=self.contact.tolist(), normal=self.normal.tolist(), directions=self.directions.tolist(),
                   gain=float(self.gain))
        return out


def _entropy(p: np.ndarray) -> float:
    p = p[p > 1e-300]
    return float(-np.sum(p * np.log2(p)))


def _to_world(h, x_model: np.ndarray) -> np.ndarray:
    """Model points ``(..., 3)`` into the world under hypothesis ``h`` (``model = s R world + t``)."""
    return ((x_model - h.translation) @ h.rotation) / h.scale


def _to_model(h, x_world: np.ndarray) -> np.ndarray:
    return h.scale * (x_world @ h.rotation.T) + h.translation


def _predicted(model, h, contact_w: np.ndarray, directions_w: np.ndarray, *, points: int, spacing: float):
    """The noise-free touch hypothesis ``h`` predicts at world point ``contact_w``, curves along the
    world ``directions_w``: its points in the world ``(k, 3)``, or None where the surface ends."""
    try:
        data, pose = simulate_world_touch(model, (h.rotation, h.translation, h.scale), contact_w, directions_w,
                                          points=points, spacing=spacing, sensor_frame=False)
    except ValueError:
        return None
    return data.transformed(*pose).points


def propose(session, *, radius: float, tolerance: float = 1.0, angle: float = 60.0, candidates: int = 48,
            rng=None) -> Proposal:
    """The next touch for ``session`` (a :class:`~tactrec.session.Session` with at least one touch).

    Parameters
    ----------
    radius : float
        World units: a proposed contact lies within this distance of an earlier touch's contact.
    tolerance : float
        World units: how near to its surface every leading hypothesis must put the proposed contact.
    angle : float
        Degrees between the proposed curves' directions.
    candidates : int
        Places tried on each leading hypothesis' surface.
    rng : seed or Generator
    """
    result = session.result
    if result is None or not result.ranking:
        raise ValueError("the session has no hypothesis yet: add a touch first")
    rng = np.random.default_rng(rng)
    probs = result.probabilities
    ranked = sorted(result.ranking, key=lambda h: -probs.get(h.model, 0.0))
    leading, mass = [], 0.0
    for h in ranked[:LEADING]:
        leading.append(h)
        mass += probs.get(h.model, 0.0)
        if mass >= MASS:
            break
    hyps = [(h.model, probs.get(h.model, 0.0)) for h in leading]
    if len(leading) < 2:
        return Proposal(None, None, None, 0.0, hyps, "one hypothesis holds the probability: nothing to separate")
    models = {e.name: e.model for e in session.recognizer.models}
    weights = np.array([w for _, w in hyps])
    weights = weights / weights.sum()
    # the hypotheses told apart: each leading model at each of its poses, sharing its probability
    poses, p, owner = [], [], []
    for k, (h, w) in enumerate(zip(leading, weights)):
        family = session.family(h.model)
        for pose in family:
            poses.append(dataclasses.replace(h, rotation=pose[:, :3], translation=pose[:, 3]))
            p.append(w / len(family))
            owner.append(k)
    p = np.array(p)
    by_model = np.eye(len(leading))[owner]                                       # (poses, models)
    contacts = np.array([w.contact if w.contact is not None else f.geometry.contact
                         for w, f in zip(session.world, session.features)])
    sizes = [len(c) for f in session.features for c in f.curves]
    points = int(np.median(sizes))
    spacing = float(np.median([w.spacing for w in session.world]))
    noise = float(np.median([f.noise for f in session.features]))
    se = fit_standard_error(max(noise_fit(noise), 1e-3 * spacing), 3 * points)
    best = None
    for h in leading:
        model = models[h.model]
        for site in model.random_sites(candidates, rng=rng):
            frame = model.site_frame(site)
            c = _to_world(h, frame.point)
            if np.min(np.linalg.norm(contacts - c, axis=1)) > radius:
                continue
            if not all(any(models[g.model].distance(_to_model(g, c)[None])[0] / g.scale <= tolerance
                           for g in poses if g.model == m.model) for m in leading):
                continue
            normal = frame.normal @ h.rotation                                        # model -> world direction
            start = rng.uniform(0.0, 2 * np.pi)
            t1 = frame.d1 @ h.rotation
            t2 = frame.d2 @ h.rotation
            angles = start + np.deg2rad(angle) * np.arange(3)
            directions = np.cos(angles)[:, None] * t1 + np.sin(angles)[:, None] * t2
            predicted = [_predicted(models[g.model], g, c, directions, points=points, spacing=spacing) for g in poses]
            if any(x is None for x in predicted):    # a touch every pose can take: the true surface reaches too
                continue
            d = np.array([[0.0 if i == j else float(np.mean(models[g.model].distance(_to_model(g, x)))) / g.scale
                           for j, g in enumerate(poses)] for i, x in enumerate(predicted)])   # (i truth, j fitted)
            with np.errstate(under="ignore"):
                after = p[None, :] * np.exp(-0.5 * np.minimum((d / se) ** 2, 1400.0))
                after = after / after.sum(axis=1, keepdims=True)
                gain = _entropy(p @ by_model) - float(sum(p[i] * _entropy(after[i] @ by_model) for i in range(len(p))))
            if best is None or gain > best[0]:
                best = (gain, c, normal / np.linalg.norm(normal), directions)
    if best is None:
        return Proposal(None, None, None, 0.0, hyps, f"no place within {radius:g} of the touches that every "
                        f"leading hypothesis puts on the surface (tolerance {tolerance:g})")
    return Proposal(best[1], best[2], best[3], best[0], hyps)
