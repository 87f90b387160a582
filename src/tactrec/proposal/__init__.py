"""Where to touch next: the touch that best separates a session's leading hypotheses.

The hypotheses are the session's models, each at its joint pose
(:mod:`tactrec.session`), with their probabilities.  The *leading* ones are
the most probable, until they hold :data:`MASS` of the models' probability
(``unknown``'s aside; at most :data:`LEADING`).  With one left that holds
:data:`MASS` of all the probability there is nothing to separate and nothing
is proposed (with less, a touch to confirm it is: below).  Where no place
suits every leading hypothesis (below), the least probable is left out
until one does, down to the two most probable; the proposal lists the
hypotheses it separates.

Candidates.  Places where the leading hypotheses disagree
(:mod:`tactrec.proposal.disagreement`): each hypothesis' surface is drawn
over the whole object, carried into the world by its pose, and the places
within ``radius`` of an earlier contact, on the side the earlier touches
came from, those where the nearest rival's surface lies farthest in
standard errors of the difference (the touches' noise and how far each
pose may still move there) are tried in turn, until ``candidates`` lines
qualify (of at most :data:`TRIED` times as many).  At each, the sensor is sent
along an *approach line*: from :data:`STANDOFF` x ``radius`` outside the
place along its outward normal, inwards, twice that far (a line that starts
inside some hypothesis' surface is no candidate).  Under every pose of every
leading hypothesis the line's outcome is predicted: where it first meets the
surface (:func:`tactrec.missed.first_hit`), and there the touch the
sensor would record, or that it meets nothing.  The place need not lie on
every hypothesis' surface: a line that one hypothesis says meets the surface
8 mm before another does separates them best.  A predicted curve runs up to
where the surface turns an edge (the part a closest-point projection can
follow); a pose whose surface there keeps less than :data:`~tactrec.proposal.predict.KEPT` of each
curve is not a truth for that line.

Gain.  At a candidate, each pose predicts the outcome: three curves through
where the line meets its surface, in the same world directions, as the
session's touches are (their points per curve and spacing), noise-free, or
no contact.  A session of single contacts (:func:`contacts_only`) is sent a
contact, not curves: each pose predicts the point where the line meets its
surface (the line sampled at :func:`tactrec.missed.line_step`; the contact's
normal is not counted in the gain).  If a pose that meets nothing is true, a model is weighed by its
pose the line cuts least (:func:`tactrec.missed.cut_depth`, in the
fit test's units as for a missed line, :mod:`tactrec.missed`).  If
hypothesis ``i`` is true, meets the line and model ``M`` is fitted, ``M``'s pose is refitted
to the earlier touches and ``i``'s predicted touch together, from each of
its poses: a pose the earlier touches leave free, along a cylinder or over
a flat patch, slides to absorb what it can.  The refit is one Gauss-Newton
step on the point-to-plane residuals (:func:`~tactrec.proposal.gain.refit`): with ``r`` the
predicted points' signed distances to ``M``, ``J`` their pose Jacobian and
``H0 = J0^T J0`` the earlier touches' (whose residuals are at their
optimum), the step is ``-(H0 + J^T J)^-1 J^T r``.  What is left is counted in
the currency of the probabilities (:mod:`tactrec.probability`): how much the
session's mean distance on ``M`` would rise over the truth's, each point's
offset ``e`` adding the folded normal's mean at ``e`` less the half-normal's
(:func:`~tactrec.proposal.gain.excess`), in standard errors of a difference of two such means
(``z_iM``, :func:`~tactrec.proposal.gain.separation`).  The noise sigma is the session's: the
touches' own, or the best joint fit's if that is larger.  After the touch,
model ``M``'s probability is weighted by ``exp(-z_iM^2 / 2)``, the true
model's by 1.  ``unknown`` counts too: where the true pose meets the line,
the touch is one its pose fits, and unknown is weighed against it as the
open world weighs a model at the fit test's edge
(:func:`tactrec.probability.open_world`); where it meets nothing there is
no fit to weigh, and unknown keeps its weight.  So of two lines that tell
the models apart alike, the one the truths meet gains more.  What an object
not in the database would show along the line cannot be predicted: that
share gains nothing.  The expected gain is how far the probabilities after
the touch, unknown's included, diverge from those now (Kullback-Leibler,
bits), expected over the truths: never negative, and 0 for a line that
changes nothing.  With one hypothesis left
that holds less than :data:`MASS` of the probability (``unknown`` holding the
rest), a touch that its pose predicts is proposed to confirm it (each touch a pose fits makes unknown
less likely, :mod:`tactrec.probability`): the line of a place on its surface
farthest from the earlier contacts among those its pose predicts to meet,
its gain the entropy between the model and unknown (what the touch can
settle).

Locating. The predictions above are only as good as the poses: where no
leading hypothesis' pose fits the evidence (the touches kept as well as
their noise allows, :meth:`tactrec.session.Session.fitted_at`, and no line
that met nothing cut beyond the fit test: the session's searches have not
found the object's pose, or the object is none of the models), a line
predicted from them tends to miss the object again and again. What is known
then is where the object is: at the touches' points. The line proposed runs
through the earlier touches' point farthest from every contact (so the new
touch widens the touched span), along that touch's own normal (on its
outward side where the touch gives one, else on the side the leading poses'
outward normals there put the outside, each voting by its probability),
:data:`STANDOFF` x ``radius``
outside it and twice that far, so it meets the object at that point or
before; the first curve runs away from the nearest contact. The next
touch's search, scored with the earlier touches, looks for the pose again.
Its gain is not predicted: the proposal reports the entropy of the
outcomes, ``unknown``'s included, the most a touch can settle. Points whose
line would start inside the most probable hypothesis' surface among those
that put the outside on that side are passed over, as are lines already
followed that met nothing; the poses that do not fit say nothing of where
the object is not.
Where no line suits the leading hypotheses (below), the touches are
located the same way.

Choice.  The gain saturates: after one touch, most places that qualify
separate the leading hypotheses at their poses completely, and their gains
lie within a hundredth of a bit of the entropy.  It cannot see the other
poses of the rival models, which the session's searches find, and a touch
beside an earlier one leaves a patch that such poses still fit.  So the
places whose gain lies within :data:`TIE` of the entropy of the best are
taken as equally good, and the one farthest from every earlier contact,
which widens the touched span most, is proposed.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..io.session import MissedLine
from ..linalg import times
from ..probability import CONSISTENT_SE
from ..missed import depth_excess, line_step
from .disagreement import places, touched_side
from .gain import entropy, expected_gain, information, separation
from .locate import fan, locate
from .predict import Seen, outcome, to_model

__all__ = ["Proposal", "propose", "leading_hypotheses", "contacts_only", "MASS", "LEADING", "STANDOFF", "CANDIDATES"]

#: the leading hypotheses of a session hold this much probability, and are at most this many
MASS, LEADING = 0.99, 4

#: an approach line starts this fraction of ``radius`` outside its place and runs twice as far
STANDOFF = 0.5
#: lines scored on each leading hypothesis' surface, the most disagreeing places whose line qualifies:
#: every line is cast and predicted under every pose of every leading hypothesis
CANDIDATES = 12
#: places tried for them, at most this many times ``candidates``, most disagreeing first
TRIED = 4
#: places whose expected gain lies within this fraction of the entropy (the most a touch can gain) of
#: the best place's are as good: the one farthest from the earlier contacts among them is proposed
TIE = 0.05


@dataclasses.dataclass(frozen=True)
class Proposal:
    """A proposed touch, world frame (``contact`` None when nothing is left to separate).

    Attributes
    ----------
    contact, normal : (3,) float or None
        Where the sensor should meet the surface, and the outward normal there (approach along
        ``-normal``), under the most probable hypothesis.
    directions : (3, 3) float or None
        Tangent directions of the curves to trace (None for a session of single contacts: the sensor
        records where it meets the surface).
    gain : float
        Expected information gain, bits.
    hypotheses : list of (str, float)
        The hypotheses the proposal separates (the leading ones, or the most probable of them that
        some place suits) and their probabilities.
    reason : str
        Why nothing is proposed, when nothing is.
    approach : MissedLine or None
        The line the sensor follows until it meets the object (``start``, ``direction``,
        ``length``), world frame.
    """

    contact: np.ndarray | None
    normal: np.ndarray | None
    directions: np.ndarray | None
    gain: float
    hypotheses: list
    reason: str = ""
    approach: MissedLine | None = None

    def to_json(self) -> dict:
        out = {"hypotheses": [{"model": m, "probability": float(p)} for m, p in self.hypotheses]}
        if self.contact is None:
            out.update(contact=None, gain=0.0, reason=self.reason)
            return out
        out.update(contact=self.contact.tolist(), normal=self.normal.tolist(), gain=float(self.gain))
        if self.directions is not None:
            out["directions"] = self.directions.tolist()
        if self.approach is not None:
            out["approach"] = self.approach.to_json()
        return out


def leading_hypotheses(result) -> list:
    """The most probable hypotheses of a session's ``result`` (:class:`~tactrec.session.SessionResult`),
    until they hold :data:`MASS` of the models' probability (``unknown``'s aside), at most
    :data:`LEADING`: those :func:`propose` separates."""
    probs = result.probabilities
    total = sum(probs.values())
    out, mass = [], 0.0
    for h in sorted(result.ranking, key=lambda h: -probs.get(h.model, 0.0))[:LEADING]:
        out.append(h)
        mass += probs.get(h.model, 0.0)
        if mass >= MASS * total:
            break
    return out


def propose(session, *, radius: float, angle: float = 60.0, candidates: int = CANDIDATES, rng=None) -> Proposal:
    """The next touch for ``session`` (a :class:`~tactrec.session.Session` with at least one touch).

    Parameters
    ----------
    radius : float
        World units: a proposed place lies within this distance of an earlier touch's contact.
    angle : float
        Degrees between the proposed curves' directions.
    candidates : int
        Places within reach tried on each leading hypothesis' surface.
    rng : seed or Generator
    """
    result = session.result
    if result is None or not result.ranking:
        raise ValueError("the session has no hypothesis yet: add a touch first")
    rng = np.random.default_rng(rng)
    probs = result.probabilities
    leading = leading_hypotheses(result)
    hyps = [(h.model, probs.get(h.model, 0.0)) for h in leading]
    if len(leading) < 2 and probs.get(leading[0].model, 0.0) >= MASS:
        return Proposal(None, None, None, 0.0, hyps, "one hypothesis holds the probability: nothing to separate")
    # no leading pose fits the touches and the lines that met nothing: none predicts where the object
    # is, the touches do; where it has no line, the fall-backs below need not ask again
    unfit = not any(pose_fits(session, h) for h in leading)
    located = _located(session, leading, hyps, radius=radius, angle=angle) if unfit else None
    if located is not None:
        return located

    def fallback():
        """Where no line suits the leading hypotheses: the touches located, unless that was tried."""
        return None if unfit else _located(session, leading, hyps, radius=radius, angle=angle)

    if len(leading) < 2:
        sure = probs.get(leading[0].model, 0.0)
        # one model against unknown: a touch its pose predicts, as far from the others as reach allows
        confirm = _best_line(session, leading, np.ones(1), radius=radius, angle=angle, candidates=candidates,
                             rng=rng)
        if confirm is None:
            return fallback() or Proposal(
                None, None, None, 0.0, hyps, f"no approach line within {radius:g} of the touches that "
                f"{leading[0].model} takes")
        _, contact, normal, directions, line = confirm
        gain = entropy(np.array([sure, 1.0 - sure]))
        return Proposal(contact, normal, directions, gain, hyps, approach=line)
    for n in range(len(leading), 1, -1):
        # the most probable hypotheses that some reachable line suits
        best = _best_line(session, leading[:n], np.array([w for _, w in hyps[:n]]), radius=radius, angle=angle,
                          candidates=candidates, rng=rng)
        if best is not None:
            gain, contact, normal, directions, line = best
            return Proposal(contact, normal, directions, gain, hyps[:n], approach=line)
    return fallback() or Proposal(
        None, None, None, 0.0, hyps, f"no approach line within {radius:g} of the touches whose outcome the two "
        "leading hypotheses both predict")


def contacts_only(session) -> bool:
    """Whether every touch ``session`` keeps is of single contacts: the next one is proposed as a contact,
    where the approach line meets the surface, not as curves to trace."""
    return all(session.world[i].contacts is not None for i in session.kept())


def pose_fits(session, h) -> bool:
    """Whether hypothesis ``h``'s pose fits the touches kept as well as their noise allows and cuts
    into no line that met nothing (by the fit test, :mod:`tactrec.probability`).  The joint pose
    is the one tested, as it is the one the probabilities weigh, not the family's others."""
    if not session.fitted_at(h.error, session.kept()):
        return False
    ev = session.result.evidence
    if ev is None or ev.misses is None or not np.size(ev.misses) or h.model not in ev.models:
        return True
    return float(np.max(np.asarray(ev.misses)[list(ev.models).index(h.model)])) <= CONSISTENT_SE


def _located(session, leading: list, hyps: list, *, radius: float, angle: float) -> Proposal | None:
    """The proposal of :func:`~tactrec.proposal.locate.locate`'s line (module text, Locating), or None
    where there is none."""
    found = locate(session, leading, standoff=STANDOFF * radius, angle=angle)
    if found is None:
        return None
    contact, normal, directions, line = found
    directions = None if contacts_only(session) else directions
    rest = max(1.0 - sum(w for _, w in hyps), 0.0)
    return Proposal(contact, normal, directions, entropy(np.array([w for _, w in hyps] + [rest])), hyps,
                    approach=line)


def _best_line(session, leading: list, weights: np.ndarray, *, radius: float, angle: float, candidates: int, rng):
    """The approach line of largest expected gain among ``leading`` hypotheses (probabilities
    ``weights``): ``(gain, contact, normal, directions, line)``, or None where no line qualifies."""
    models = {e.name: e.model for e in session.recognizer.models}
    unknown = float(session.result.unknown)
    weights = (1.0 - unknown) * weights / weights.sum()
    use = session.kept()
    x_world = np.concatenate([session.features[i].points for i in use])
    # each leading model at each of its poses; the poses share the model's probability as truths and
    # are the starts of its refits
    poses, p, owner, info, arrays = [], [], [], [], []
    for k, (h, w) in enumerate(zip(leading, weights)):
        family = session.family(h.model)
        for pose in family:
            poses.append(dataclasses.replace(h, rotation=pose[:, :3], translation=pose[:, 3]))
            p.append(w / len(family))
            owner.append(k)
            arrays.append(pose)
            info.append(information(models[h.model], pose, h.scale, x_world))
    p, owner = np.array(p), np.array(owner)
    by_model = np.eye(len(leading))[owner]                                       # (poses, models)
    contacts = session.contacts()
    reached = contacts[use]                                   # the touches kept: where the object was met
    sizes = [len(c) for f in session.features for c in f.curves]
    points = int(np.median(sizes))
    spacing = float(np.median([w.spacing for w in session.world]))
    single = contacts_only(session)
    noise = float(np.median([f.noise for f in session.features]))
    sigma = max(noise, leading[0].error * np.sqrt(np.pi / 2), 1e-3 * spacing)
    limit = session.limit(use)
    standoff = STANDOFF * radius
    before = entropy(np.append(weights, unknown))
    found = []
    for k, h in enumerate(leading):
        model = models[h.model]
        first = int(np.argmax(owner == k))                                  # the model's joint pose
        rivals = [(poses[j], arrays[j], info[j]) for j in np.nonzero(owner != k)[0]]
        side = touched_side(model, poses[first], reached)
        ranked = places(models, poses[first], arrays[first], info[first], rivals, reached, side, radius=radius,
                        sigma=sigma, rng=rng)
        taken = 0
        for place in ranked[:TRIED * candidates]:      # the most disagreeing, until ``candidates`` lines qualify
            if taken >= candidates:
                break
            c, normal = place.point, place.normal
            line = MissedLine(c + standoff * normal, -normal, 2.0 * standoff)
            if any(models[g.model].planes(to_model(g, line.start)[None])[0][0] <= 0.0 for g in poses):
                continue                                                  # starts inside some pose's surface
            start = rng.uniform(0.0, 2 * np.pi)
            frame = model.site_frame(place.site)
            t1 = times(frame.d1, h.rotation)
            t2 = times(frame.d2, h.rotation)
            directions = None if single else fan(t1, t2, angle, start)
            outcomes = [outcome(models[g.model], g, line, directions, step=line_step(spacing, line.length),
                                points=points, spacing=spacing) for g in poses]
            takes = np.array([o.seen is not Seen.UNTAKEN for o in outcomes])
            if not np.all(by_model[takes].any(axis=0)):   # every model has a pose that predicts the outcome
                continue
            hits = np.array([o.seen is Seen.HIT for o in outcomes])
            if len(leading) == 1 and not hits.any():      # a touch to confirm a pose must meet its surface
                continue
            # the truths: the poses with an outcome, each model keeping its probability
            truth = p * takes / np.sum(by_model * (by_model[takes].sum(axis=0) / by_model.sum(axis=0)), axis=1)
            z = np.zeros((len(poses), len(leading)))                    # (truth pose, model fitted)
            missing = np.array([o.seen is Seen.MISS for o in outcomes])
            if missing.any():                # a truth that meets nothing: each model by its pose the line cuts least
                cut = depth_excess([o.depth for o in outcomes], limit)
                for j in range(len(leading)):
                    z[missing & (owner != j), j] = cut[owner == j].min()
            if hits.any():
                stacked = np.array([o.points for o in outcomes if o.seen is Seen.HIT])
                kept = np.array([o.kept for o in outcomes if o.seen is Seen.HIT])
                for j in range(len(leading)):
                    others = (owner != j)[hits]
                    if not others.any():
                        continue
                    sep = np.min([separation(models[poses[i].model], poses[i], info[i], stacked[others], sigma,
                                              len(x_world), kept[others]) for i in np.nonzero(owner == j)[0]],
                                 axis=0)
                    z[np.nonzero(hits)[0][others], j] = sep
            gain = expected_gain(weights, unknown, z, hits, truth, takes)
            contact = outcomes[0].hit   # where the most probable hypothesis' joint pose (its family's first) meets it
            found.append((gain, c if contact is None else contact, normal, directions, line))
            taken += 1
    return choose(found, contacts, before)


def choose(found: list, contacts: np.ndarray, entropy: float):
    """The line proposed among ``found``, ``(gain, contact (3,), normal, directions, line)`` each: of those
    whose gain lies within :data:`TIE` x ``entropy`` (bits) of the largest, the one farthest from
    every earlier contact (world ``contacts (N, 3)``), the larger gain on a tie; None for none."""
    if not found:
        return None
    top = max(f[0] for f in found)
    near = [f for f in found if f[0] >= top - TIE * entropy]
    return max(near, key=lambda f: (float(np.min(np.linalg.norm(contacts - f[1], axis=1))), f[0]))
