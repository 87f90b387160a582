"""What an approach line meets under a hypothesis' pose, and the touch the sensor would record there
(:mod:`tactrec.proposal`)."""

from __future__ import annotations

import dataclasses
import enum

import numpy as np

from ..linalg import times
from ..missed import crossing

__all__ = ["KEPT", "Seen", "Prediction", "to_world", "to_model", "predicted", "outcome"]


class Seen(enum.Enum):
    """What an approach line meets under a pose."""

    #: the surface, where it takes the touch the sensor would trace
    HIT = "hit"
    #: nothing: the line passes the surface by
    MISS = "miss"
    #: the surface, where it will not take the touch (it turns an edge within the curves' length)
    UNTAKEN = "untaken"


@dataclasses.dataclass(frozen=True)
class Prediction:
    """A line's outcome under one pose (:func:`outcome`): what it meets, the touch predicted there
    (``points (k, 3)`` world frame and which were predicted, ``kept (k,)``; None unless ``HIT``),
    where it first meets the surface (``hit (3,)`` world, None for a miss) and how far it cuts into
    the surface (``depth``, world units)."""

    seen: Seen
    points: np.ndarray | None
    kept: np.ndarray | None
    hit: np.ndarray | None
    depth: float

#: a predicted curve is taken up to where the surface turns an edge, and must keep this share of its points
KEPT = 0.25


def to_world(h, x_model: np.ndarray) -> np.ndarray:
    """Model points ``(..., 3)`` into the world under hypothesis ``h`` (``model = s R world + t``)."""
    return times(x_model - h.translation, h.rotation) / h.scale


def to_model(h, x_world: np.ndarray) -> np.ndarray:
    return h.scale * times(x_world, h.rotation.T) + h.translation


def predicted(model, h, contact_w: np.ndarray, directions_w: np.ndarray, *, points: int, spacing: float):
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
    c = s * times(contact_w, R.T) + t
    d = times(directions_w, R.T)
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
    return times(x - t, R) / s, kept.reshape(-1)


def outcome(model, pose, line, directions, *, step: float, points: int, spacing: float) -> Prediction:
    """What ``line`` gives under ``pose`` (:class:`Prediction`): where it meets the surface and how far
    it cuts into it (:func:`tactrec.missed.crossing`), and there the touch the sensor would record
    (:func:`predicted`), or that the surface there will not take it.  ``directions`` None: the sensor
    records a single contact, where the line meets the surface (any surface takes it)."""
    hit, depth = crossing(model, pose, line, step)
    if hit is None:
        return Prediction(Seen.MISS, None, None, None, depth)
    if directions is None:
        return Prediction(Seen.HIT, hit[None], np.ones(1, dtype=bool), hit, depth)
    x = predicted(model, pose, hit, directions, points=points, spacing=spacing)
    if x is None:
        return Prediction(Seen.UNTAKEN, None, None, hit, depth)
    return Prediction(Seen.HIT, x[0], x[1], hit, depth)
