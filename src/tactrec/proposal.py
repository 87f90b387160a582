"""Where to touch next: the touch that best separates a session's leading hypotheses.

The hypotheses are the session's models, each at its joint pose
(:mod:`tactrec.session`), with their probabilities.  The *leading* ones are
the most probable, until they hold :data:`MASS` of the models' probability
(``unknown``'s aside; at most :data:`LEADING`).  With one left that holds
:data:`MASS` of all the probability there is nothing to separate and nothing
is proposed (with less, a touch to confirm it is: below).  Where no place suits every leading hypothesis (below), the least
probable is left out until one does, down to the two most probable; the
proposal lists the hypotheses it separates.

Candidates.  Places on the leading hypotheses' surfaces within ``radius`` of
an earlier touch's contact (``candidates`` random sites of each model in that
reach, carried into the world by its pose).  At each, the sensor is sent
along an *approach line*: from :data:`STANDOFF` x ``radius`` outside the
place along its outward normal, inwards, twice that far (a line that starts
inside some hypothesis' surface is no candidate).  Under every pose of every
leading hypothesis the line's outcome is predicted: where it first meets the
surface (:func:`tactrec.session.lines.first_hit`), and there the touch the
sensor would record, or that it meets nothing.  The place need not lie on
every hypothesis' surface: a line that one hypothesis says meets the surface
8 mm before another does separates them best.  A predicted curve runs up to
where the surface turns an edge (the part a closest-point projection can
follow); a pose whose surface there keeps less than :data:`KEPT` of each
curve is not a truth for that line.

Gain.  At a candidate, each pose predicts the outcome: three curves through
where the line meets its surface, in the same world directions, as the
session's touches are (their points per curve and spacing), noise-free, or
no contact.  If a pose that meets nothing is true, a model is weighed by its
pose the line cuts least (:func:`tactrec.session.lines.cut_depth`, in the
fit test's units as for a missed line, :mod:`tactrec.session.lines`).  If
hypothesis ``i`` is true, meets the line and model ``M`` is fitted, ``M``'s pose is refitted
to the earlier touches and ``i``'s predicted touch together, from each of
its poses: a pose the earlier touches leave free, along a cylinder or over
a flat patch, slides to absorb what it can.  The refit is one Gauss-Newton
step on the point-to-plane residuals (:func:`_refit`): with ``r`` the
predicted points' signed distances to ``M``, ``J`` their pose Jacobian and
``H0 = J0^T J0`` the earlier touches' (whose residuals are at their
optimum), the step is ``-(H0 + J^T J)^-1 J^T r``.  What is left is counted in
the currency of the probabilities (:mod:`tactrec.probability`): how much the
session's mean distance on ``M`` would rise over the truth's, each point's
offset ``e`` adding the folded normal's mean at ``e`` less the half-normal's
(:func:`_excess`), in standard errors of a difference of two such means
(``z_iM``, :func:`_separation`).  The noise sigma is the session's: the
touches' own, or the best joint fit's if that is larger.  After the touch,
model ``M``'s probability is weighted by ``exp(-z_iM^2 / 2)``, the true
model's by 1.  The expected gain is the entropy of the models' probabilities
now less its expectation over the truths after the touch, in bits.
``unknown`` is left out of the gain: what an object not in the database
would show along the line cannot be predicted.  But with one hypothesis left
that holds less than :data:`MASS` of the probability (``unknown`` holding the
rest), a touch that its pose predicts is proposed to confirm it (each touch a pose fits makes unknown
less likely, :mod:`tactrec.probability`): the line of a place on its surface
farthest from the earlier contacts among those its pose predicts to meet,
its gain the entropy between the model and unknown (what the touch can
settle).

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
from scipy.special import erf

from .io.session import MissedLine
from .registration.solver import jacobian
from .session.lines import crossing, depth_excess
from .session.result import LEADING, MASS

__all__ = ["Proposal", "propose", "MASS", "LEADING", "STANDOFF", "CANDIDATES"]

#: an approach line starts this fraction of ``radius`` outside its place and runs twice as far
STANDOFF = 0.5
#: a predicted curve is taken up to where the surface turns an edge, and must keep this share of its points
KEPT = 0.25
#: places tried on each leading hypothesis' surface: every line is cast and predicted under every pose of
#: every leading hypothesis, and past a dozen the gains tie (the farthest of the tied places is proposed)
CANDIDATES = 12


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
        out.update(contact=self.contact.tolist(), normal=self.normal.tolist(), directions=self.directions.tolist(),
                   gain=float(self.gain))
        if self.approach is not None:
            out["approach"] = self.approach.to_json()
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
    world ``directions_w`` (each centred there): its points in the world ``(k, 3)`` and which of
    them are predicted ``(k,)`` (bool), or None where the surface will not take the touch.  Each
    curve is the chord along its direction, ``spacing`` between points, projected onto the surface
    twice (closest points).  Where the projected points stop advancing (less than a quarter of
    ``spacing`` apart: projected onto an edge) the surface turns a corner the projection cannot
    follow: a curve is predicted over the run of points about the contact up to there, and a
    touch whose curves keep less than :data:`KEPT` of their points each is not predicted.  On the
    touches' scale this is their plane section to well within the noise, at the cost of one batch
    of closest-point queries (a plane section of a mesh costs a pass over all its faces)."""
    R, t, s = h.rotation, h.translation, h.scale
    c = s * (np.asarray(contact_w, dtype=np.float64) @ R.T) + t
    d = np.asarray(directions_w, dtype=np.float64) @ R.T
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    offsets = (np.arange(points) - (points - 1) / 2.0) * spacing * s
    x = model.projected((c[None, None, :] + offsets[None, :, None] * d[:, None, :]).reshape(-1, 3))
    advancing = np.linalg.norm(np.diff(x.reshape(len(d), points, 3), axis=1), axis=2) >= 0.25 * spacing * s
    centre = (points - 1) // 2                              # the run of advancing steps about the contact
    kept = np.ones((len(d), points), dtype=bool)
    kept[:, centre + 1:] = np.cumprod(advancing[:, centre:], axis=1).astype(bool)
    kept[:, :centre] = np.cumprod(advancing[:, :centre][:, ::-1], axis=1)[:, ::-1].astype(bool)
    if not np.all(kept.sum(axis=1) >= KEPT * points):
        return None
    return ((x - t) @ R) / s, kept.reshape(-1)


#: a hypothesis' surface is drawn at random up to this many times ``candidates`` for reachable places
DRAWS = 50
#: places whose expected gain lies within this fraction of the entropy (the most a touch can gain) of
#: the best place's are as good: the one farthest from the earlier contacts among them is proposed
TIE = 0.05


def _reachable(model, h, contacts: np.ndarray, radius: float, count: int, rng) -> list:
    """Up to ``count`` random places on ``model``'s surface that hypothesis ``h`` puts within ``radius``
    of an earlier contact (world ``contacts (N, 3)``): ``(SiteFrame, world point)`` pairs, drawn
    uniformly over the surface in batches until there are enough or :data:`DRAWS` x ``count`` were
    drawn."""
    out, drawn = [], 0
    while len(out) < count and drawn < DRAWS * count:
        for site in model.random_sites(4 * count, rng=rng):
            frame = model.site_frame(site)
            c = _to_world(h, frame.point)
            if np.min(np.linalg.norm(contacts - c, axis=1)) <= radius:
                out.append((frame, c))
                if len(out) >= count:
                    break
        drawn += 4 * count
    return out


def _jacobian(model, moved: np.ndarray):
    """Signed distances ``(m,)`` of model-frame points ``moved (m, 3)`` and their pose Jacobian
    ``(m, 6)``: the change of each distance under a small turn ``w`` (per model size) and shift
    ``u`` of the model frame, ``(m x n) . w + n . u``."""
    d, n = model.planes(moved)
    J = jacobian(moved, n)
    J[:, :3] /= model.size
    return d, J


def _information(model, pose: np.ndarray, scale: float, x_world: np.ndarray) -> np.ndarray:
    """``J0^T J0 (6, 6)`` of world points ``x_world (m, 3)`` under ``pose (3, 4)``, model units."""
    _, J = _jacobian(model, scale * x_world @ pose[:, :3].T + pose[:, 3])
    return np.einsum("mi,mj->ij", J, J)


def _refit(model, pose: np.ndarray, scale: float, H0: np.ndarray, x_world: np.ndarray, kept: np.ndarray):
    """Each of ``n`` predicted touches ``x_world (n, k, 3)`` against ``model`` once the pose
    ``(3, 4)`` is refitted to that touch's predicted points (``kept (n, k)``, bool) and the earlier
    touches (information ``H0 (6, 6)``) together, by one Gauss-Newton step (module text): the
    touch's signed distances after the step ``(n, k)`` (0 where not predicted) and the sum of
    squares the step adds to the earlier touches' ``(n,)``, world units."""
    n, k = x_world.shape[:2]
    r, J = _jacobian(model, (scale * x_world.reshape(-1, 3) @ pose[:, :3].T + pose[:, 3]))
    r, J = r.reshape(n, k) * kept, J.reshape(n, k, 6) * kept[..., None]
    H = H0[None] + np.einsum("nmi,nmj->nij", J, J)
    b = np.einsum("nmi,nm->ni", J, r)
    ridge = 1e-12 * np.maximum(np.trace(H, axis1=1, axis2=2), 1e-300)
    step = -np.linalg.solve(H + ridge[:, None, None] * np.eye(6), b[..., None])[..., 0]
    after = r + np.einsum("nmi,ni->nm", J, step)
    return after / scale, np.einsum("ni,ij,nj->n", step, H0, step) / scale ** 2


def _excess(offset: np.ndarray, sigma: float) -> np.ndarray:
    """What a point ``offset`` from the surface adds to a fit's mean distance under Gaussian noise of
    ``sigma``: the folded normal's mean less the half-normal's (quadratic below ``sigma``, then
    linear)."""
    a = np.abs(offset)
    with np.errstate(under="ignore"):
        folded = sigma * np.sqrt(2.0 / np.pi) * np.exp(-0.5 * (a / sigma) ** 2) + a * erf(a / (sigma * np.sqrt(2.0)))
    return folded - sigma * np.sqrt(2.0 / np.pi)


def _separation(model, h, H0: np.ndarray, predicted: np.ndarray, sigma: float, earlier: int,
                kept: np.ndarray | None = None) -> np.ndarray:
    """How many standard errors ``(n,)`` the session's mean distance on ``model``, refitted from
    pose ``h`` (module text), would exceed the truth's if each of the ``predicted (n, k, 3)``
    touches were added (their predicted points ``kept (n, k)``, bool; all by default): the points'
    excess distances (:func:`_excess`; the earlier touches' ``earlier`` points share the sum of
    squares the refit adds to them) over the spread of a difference of two fits' mean distances
    over all the points."""
    kept = np.ones(predicted.shape[:2], dtype=bool) if kept is None else np.asarray(kept, dtype=bool)
    pose = np.concatenate([h.rotation, h.translation[:, None]], axis=1)
    offsets, added = _refit(model, pose, h.scale, H0, predicted, kept)
    total = kept.sum(axis=1) + earlier
    excess = (_excess(offsets, sigma) * kept).sum(axis=1) + earlier * _excess(np.sqrt(added / earlier), sigma)
    spread = sigma * np.sqrt(1.0 - 2.0 / np.pi)                      # a half-normal distance's
    return excess / (spread * np.sqrt(2.0 * total))


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
    leading = result.leading()
    hyps = [(h.model, probs.get(h.model, 0.0)) for h in leading]
    if len(leading) < 2:
        sure = probs.get(leading[0].model, 0.0)
        if sure >= MASS:
            return Proposal(None, None, None, 0.0, hyps, "one hypothesis holds the probability: nothing to separate")
        # one model against unknown: a touch its pose predicts, as far from the others as reach allows
        confirm = _best_line(session, leading, np.ones(1), radius=radius, angle=angle, candidates=candidates,
                             rng=rng)
        if confirm is None:
            return Proposal(None, None, None, 0.0, hyps, f"no approach line within {radius:g} of the touches that "
                            f"{leading[0].model} takes")
        _, contact, normal, directions, line = confirm
        gain = _entropy(np.array([sure, 1.0 - sure]))
        return Proposal(contact, normal, directions, gain, hyps, approach=line)
    for n in range(len(leading), 1, -1):
        # the most probable hypotheses that some reachable line suits
        best = _best_line(session, leading[:n], np.array([w for _, w in hyps[:n]]), radius=radius, angle=angle,
                          candidates=candidates, rng=rng)
        if best is not None:
            gain, contact, normal, directions, line = best
            return Proposal(contact, normal, directions, gain, hyps[:n], approach=line)
    return Proposal(None, None, None, 0.0, hyps, f"no approach line within {radius:g} of the touches whose outcome "
                    "the two leading hypotheses both predict")


def _outcome(model, pose, line, directions, *, step: float, points: int, spacing: float):
    """What ``line`` gives under ``pose``, and how far it cuts into its surface (world units,
    :func:`tactrec.session.lines.crossing`): ``("miss", None, None, depth)``,
    ``("hit", (points (k, 3), kept (k,)), hit, depth)`` (the touch predicted where it meets the
    surface, at world point ``hit``: :func:`_predicted`), or ``(None, None, hit, depth)`` where the
    surface there will not take the touch."""
    hit, depth = crossing(model, pose, line, step)
    if hit is None:
        return "miss", None, None, depth
    x = _predicted(model, pose, hit, directions, points=points, spacing=spacing)
    return ("hit" if x is not None else None), x, hit, depth


def _best_line(session, leading: list, weights: np.ndarray, *, radius: float, angle: float, candidates: int, rng):
    """The approach line of largest expected gain among ``leading`` hypotheses (probabilities
    ``weights``): ``(gain, contact, normal, directions, line)``, or None where no line qualifies."""
    result = session.result
    models = {e.name: e.model for e in session.recognizer.models}
    weights = weights / weights.sum()
    use = [i for i in range(len(session.features)) if i not in result.slipped]
    x_world = np.concatenate([session.features[i].points for i in use])
    # each leading model at each of its poses; the poses share the model's probability as truths and
    # are the starts of its refits
    poses, p, owner, info = [], [], [], []
    for k, (h, w) in enumerate(zip(leading, weights)):
        family = session.family(h.model)
        for pose in family:
            poses.append(dataclasses.replace(h, rotation=pose[:, :3], translation=pose[:, 3]))
            p.append(w / len(family))
            owner.append(k)
            info.append(_information(models[h.model], pose, h.scale, x_world))
    p, owner = np.array(p), np.array(owner)
    by_model = np.eye(len(leading))[owner]                                       # (poses, models)
    contacts = np.array([w.contact if w.contact is not None else f.geometry.contact
                         for w, f in zip(session.world, session.features)])
    sizes = [len(c) for f in session.features for c in f.curves]
    points = int(np.median(sizes))
    spacing = float(np.median([w.spacing for w in session.world]))
    noise = float(np.median([f.noise for f in session.features]))
    sigma = max(noise, leading[0].error * np.sqrt(np.pi / 2), 1e-3 * spacing)
    limit = session.limit(use)
    standoff = STANDOFF * radius
    entropy = _entropy(weights)
    found = []
    for h in leading:
        model = models[h.model]
        for frame, c in _reachable(model, h, contacts, radius, candidates, rng):
            normal = frame.normal @ h.rotation                                        # model -> world direction
            normal = normal / np.linalg.norm(normal)
            line = MissedLine(c + standoff * normal, -normal, 2.0 * standoff)
            if any(models[g.model].planes(_to_model(g, line.start)[None])[0][0] <= 0.0 for g in poses):
                continue                                                  # starts inside some pose's surface
            start = rng.uniform(0.0, 2 * np.pi)
            t1 = frame.d1 @ h.rotation
            t2 = frame.d2 @ h.rotation
            angles = start + np.deg2rad(angle) * np.arange(3)
            directions = np.cos(angles)[:, None] * t1 + np.sin(angles)[:, None] * t2
            outcomes = [_outcome(models[g.model], g, line, directions, step=spacing, points=points, spacing=spacing)
                        for g in poses]
            kinds = np.array([o[0] for o in outcomes], dtype=object)
            takes = kinds != None  # noqa: E711
            if not np.all(by_model[takes].any(axis=0)):   # every model has a pose that predicts the outcome
                continue
            hits = kinds == "hit"
            if len(leading) == 1 and not hits.any():      # a touch to confirm a pose must meet its surface
                continue
            # the truths: the poses with an outcome, each model keeping its probability
            truth = p * takes / (by_model @ (by_model[takes].sum(axis=0) / by_model.sum(axis=0)))
            z = np.zeros((len(poses), len(leading)))                    # (truth pose, model fitted)
            missing = (kinds == "miss")
            if missing.any():                # a truth that meets nothing: each model by its pose the line cuts least
                cut = depth_excess([o[3] for o in outcomes], limit)
                for k in range(len(leading)):
                    z[missing & (owner != k), k] = cut[owner == k].min()
            if hits.any():
                stacked = np.array([o[1][0] for o, hit in zip(outcomes, hits) if hit])
                kept = np.array([o[1][1] for o, hit in zip(outcomes, hits) if hit])
                for k in range(len(leading)):
                    others = (owner != k)[hits]
                    if not others.any():
                        continue
                    sep = np.min([_separation(models[poses[j].model], poses[j], info[j], stacked[others], sigma,
                                              len(x_world), kept[others]) for j in np.nonzero(owner == k)[0]],
                                 axis=0)
                    z[np.nonzero(hits)[0][others], k] = sep
            with np.errstate(under="ignore"):
                after = weights[None, :] * np.exp(-0.5 * np.minimum(z * z, 1400.0))
                after = after / after.sum(axis=1, keepdims=True)
            gain = entropy - float(sum(truth[i] * _entropy(after[i]) for i in np.nonzero(takes)[0]))
            contact = outcomes[0][2]      # where the most probable hypothesis' joint pose (its family's first) meets it
            found.append((gain, c if contact is None else contact, normal, directions, line))
    return _chosen(found, contacts, entropy)


def _chosen(found: list, contacts: np.ndarray, entropy: float):
    """The line proposed among ``found``, ``(gain, contact (3,), normal, directions, line)`` each: of those
    whose gain lies within :data:`TIE` x ``entropy`` (bits) of the largest, the one farthest from
    every earlier contact (world ``contacts (N, 3)``), the larger gain on a tie; None for none."""
    if not found:
        return None
    top = max(f[0] for f in found)
    near = [f for f in found if f[0] >= top - TIE * entropy]
    return max(near, key=lambda f: (float(np.min(np.linalg.norm(contacts - f[1], axis=1))), f[0]))
