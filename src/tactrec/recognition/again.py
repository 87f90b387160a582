"""The searches a recognition makes again: where the first search of a touch cannot be the last.

Both are part of the one path from a touch to a result (:meth:`tactrec.recognition.Recognizer.recognize`):

* :func:`judge_ends` -- a touch whose sensor slips (it had outliers, :mod:`tactrec.outliers`): its
  curves' end points, which the spike residual cannot judge, are judged by the fit instead;
* :func:`other_meetings` -- curves that miss each other beyond their noise may meet at more than one
  point within the tolerance (:func:`~tactrec.io.meeting.meeting_points`: the far face of a thin
  plate); where the search from the first finds no fit, each other is searched in turn.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError
from ..features import Touch
from ..io.meeting import MEETING, meeting, meeting_points
from ..outliers import ALPHA, ends_off, judged_ends, without

__all__ = ["judge_ends", "other_meetings", "missing", "best_error"]


def best_error(outcome) -> float:
    """The least error of an outcome's accepted registrations, data units (inf for none)."""
    return min((r.error / r.scale for r in outcome.ranking if r.ok), default=np.inf)


def missing(touch: Touch) -> bool:
    """Whether the touch's curves miss each other: a curve passes its meeting point farther than its
    noise allows (``k`` sigma, ``k = sqrt(2 ln(m / ALPHA))`` for ``m`` points, as
    :mod:`tactrec.outliers` bounds them).  Curves that pass through one point were traced there."""
    k = np.sqrt(2.0 * np.log(max(len(touch.points), 1) / ALPHA))
    return bool(meeting(touch.data)[1].max() > k * touch.noise)


def other_meetings(data, touch: Touch, outcome, searched, fits, budget: int | None):
    """``touch`` and its search's ``outcome``, or the touch and outcome of another meeting point of
    ``data``'s curves (closest first) whose best error is lower: each is searched in turn
    (``searched(data, budget) -> (touch, outcome)``) until one's best fits (``fits(touch, outcome)``)
    or ``budget`` (the work of all the searches, None: none) is spent.  A meeting point the
    estimate cannot take (curves tangent at it) is not the contact."""
    for contact in meeting_points(touch.data.curves, MEETING * touch.data.spacing)[1:]:
        left = None if budget is None else budget - outcome.work
        if left is not None and left <= 0:
            break
        try:
            other, found = searched(dataclasses.replace(data, contact=contact), left)
        except InputError:
            continue
        work = outcome.work + found.work
        allowed = None if outcome.allowed is None or found.allowed is None else outcome.allowed + found.allowed
        if best_error(found) < best_error(outcome):
            touch, outcome = other, found
        outcome = dataclasses.replace(outcome, work=work, allowed=allowed)
        if fits(touch, outcome):
            break
    return touch, outcome


def judge_ends(touch, search, refit, residuals, estimation: dict):
    """The touch (a :class:`~tactrec.features.Touch` with outliers) without the curves' end points off
    the registration (module text), and the search's outcome on it: ``search(touch)`` the method's
    search, ``refit(outcome, touch)`` the method's refit of a search's registrations on a touch of
    nearly the same points (:meth:`~tactrec.methods.base.Method.refit`), ``residuals(registration,
    touch)`` the signed distances of the touch's points under a registration's pose, ``estimation``
    the keywords of :meth:`~tactrec.features.Touch.from_data`.

    The judged points alone (each curve without its judged ends, :func:`judged_ends`) are searched;
    the ends are judged under that search's best pose (:func:`ends_off`); its registrations are
    refitted on the points left where it settled, and the points left searched again where it did
    not, the work of both added.  Where no end can be judged, the judged points are too few to be a
    touch, or their search registers nothing, the touch is searched as it is; where setting the ends
    aside leaves no touch the package takes, they are kept."""
    judged = judged_ends(touch.data.curves, meeting(touch.data)[0])
    count = int(sum(int(m.sum()) for m in judged))
    if not count:
        return touch, search(touch)
    try:
        inner = Touch.from_data(without(touch.data, judged, count), **estimation)
    except InputError:
        return touch, search(touch)
    first = search(inner)
    best = min((r for r in first.ranking if r.ok), key=lambda r: (r.error / r.scale, r.model), default=None)
    if best is None:
        return touch, _both(first, search(touch))
    marks = ends_off(touch.curves, residuals(best, touch), touch.noise, touch.data.spacing, judged)
    off = int(sum(int(m.sum()) for m in marks))
    if off:
        try:
            again = Touch.from_data(without(touch.data, marks, touch.outliers + off), **estimation)
        except InputError:                     # the ends are what makes it a touch: they are kept
            return touch, _carried(first, touch, search, refit)
        touch = dataclasses.replace(again, outliers=touch.outliers + off + again.outliers)
    return touch, _carried(first, touch, search, refit)


def _carried(first, touch, search, refit):
    """The outcome of ``first``, the judged points' search, on ``touch``: refitted where it settled (its
    best is a fit, or clear of every other model), searched again where it did not (its registrations
    are then no more than where its budget stopped)."""
    return refit(first, touch) if first.settled else _both(first, search(touch))


def _both(first, found):
    """The outcome ``found`` with the work and the budget of ``first`` added, settled only when both were."""
    allowed = None if first.allowed is None or found.allowed is None else first.allowed + found.allowed
    return dataclasses.replace(found, work=found.work + first.work, allowed=allowed,
                               settled=bool(first.settled and found.settled))
