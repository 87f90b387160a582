"""Where the object is when no pose fits: an approach line through a touched point (:mod:`tactrec.proposal`,
Locating)."""

from __future__ import annotations

import numpy as np

from ..io.session import MissedLine
from ..linalg import dot3, norm3, times
from .predict import to_model

__all__ = ["locate", "tried", "fan"]


def locate(session, leading: list, *, standoff: float, angle: float):
    """The approach line through an earlier touch's point (:mod:`tactrec.proposal`, Locating), starting
    ``standoff`` outside it and running twice as far: ``(contact, normal, directions, line)``, world
    frame, or None where every such line starts inside the most probable hypothesis' surface on its
    side, or was followed before and met nothing."""
    models = {e.name: e.model for e in session.recognizer.models}
    kept = session.kept()
    x = np.concatenate([session.features[i].points for i in kept])
    each = [len(session.features[i].points) for i in kept]
    data = np.repeat([session.features[i].geometry.normal for i in kept], each, axis=0)   # each touch's own normal
    known = np.repeat([session.features[i].geometry.oriented for i in kept], each)       # its outward side given
    contacts = session.contacts()
    gap = np.linalg.norm(x[:, None, :] - contacts[None, :, :], axis=2)
    order = np.argsort(-gap.min(axis=1), kind="stable")
    outward = data[order] / np.linalg.norm(data[order], axis=1, keepdims=True)
    # the side: the leading poses' outward normals vote, each by its probability
    probs = session.result.probabilities
    vote, agree = np.zeros(len(order)), []
    for g in leading:
        _, n = models[g.model].planes(to_model(g, x[order]))
        dots = dot3(times(n, g.rotation), outward)
        vote += probs.get(g.model, 0.0) * np.sign(np.nan_to_num(dots))
        agree.append(dots)
    side = np.where(known[order] | (vote >= 0.0), 1.0, -1.0)         # a touch's own outward side stands
    outward *= side[:, None]
    starts = x[order] + standoff * outward
    # no leading pose fits the touches, so none says where the object is not: the line need only start
    # outside the most probable pose that puts the outside on that side
    inside = np.zeros(len(order), dtype=bool)
    checked = np.zeros(len(order), dtype=bool)
    for g, dots in zip(leading, agree):
        mine = ~checked & (dots * side > 0.0)
        if mine.any():
            inside[mine] = models[g.model].planes(to_model(g, starts[mine]))[0] <= 0.0
            checked |= mine
    inside |= tried(session.misses, x[order], outward)                # a line that met nothing is not sent again
    if inside.all():
        return None
    k = int(np.argmax(~inside))                      # the farthest point whose line starts outside it
    p, normal = x[order[k]], outward[k]
    away = p - contacts[np.argmin(gap[order[k]])]              # from the nearest contact, in the tangent plane
    away = away - dot3(away, normal) * normal
    if norm3(away) <= 1e-12 * max(standoff, 1.0):
        away = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal))])
    t1 = away / norm3(away)
    return p, normal, fan(t1, np.cross(normal, t1), angle), MissedLine(starts[k], -normal, 2.0 * standoff)


def tried(misses: list, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Which of the lines through ``points (n, 3)`` along ``directions (n, 3)`` (unit, outward) an
    earlier line that met nothing already followed: it ran through the point (within a
    thousandth of its length) along the same direction."""
    out = np.zeros(len(points), dtype=bool)
    for line in misses:
        d = np.asarray(line.direction, dtype=np.float64)
        off = points - np.asarray(line.start, dtype=np.float64)
        along = np.clip(dot3(off, d), 0.0, line.length)
        near = np.linalg.norm(off - along[:, None] * d, axis=1) <= 1e-3 * line.length
        out |= near & (dot3(directions, d) <= -0.999)
    return out


def fan(t1: np.ndarray, t2: np.ndarray, angle: float, start: float = 0.0) -> np.ndarray:
    """Three curve directions ``(3, 3)`` in the plane of the unit vectors ``t1``, ``t2``: at ``start``
    (radians from ``t1``) and ``angle`` and twice ``angle`` degrees on."""
    angles = start + np.deg2rad(angle) * np.arange(3)
    return np.cos(angles)[:, None] * t1 + np.sin(angles)[:, None] * t2
