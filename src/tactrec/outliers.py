"""Points a sensor recorded off the trace (slips, spikes): which a touch sets aside, by one rule.

A real sensor gives a few outliers: points moved off the curve it traced.
They would tilt the local fit at the contact (:mod:`tactrec.estimation`:
the normal, the principal curvatures, the noise level) and pull every
point-to-plane step of a registration (:mod:`tactrec.registration.solver`)
and its error.  A touch therefore sets them aside before either sees the
data: its curves, estimate, noise, registrations, errors and probabilities
are those of the points it keeps (:meth:`tactrec.features.Touch.from_data`),
and the recognition reports how many it set aside
(:attr:`tactrec.recognition.Recognition.outliers`).

The residual.  Each point ``x_i`` is predicted from its three neighbours on
one side: the quadratic through them in chord length, extrapolated by the
chord ``|x_i - x_{i-1}|`` (or ``|x_i - x_{i+1}|``); its residual on that side
is ``x_i`` minus the prediction, across the extrapolated tangent (a 2-vector:
in the curve's plane and out of it; a point moved along the curve is not off
the trace).  The point's residual ``r_i`` is the smaller of its two
sides' (a curve's first and last three points have one side only, which
cannot tell a spike from a turn of the curve, and are not judged here).  A
spike is off both sides' predictions; a corner (a sharp edge, a mesh
section's facets) lies on the piece of the curve on either side of it, so
one side predicts it; and the neighbours of a spike are predicted by their
other side, so one spike does not mark its neighbours.  The rule is made
for isolated spikes, a few per cent of the points.

The scale and the bound.  Under Gaussian noise of sigma per coordinate, each
side's residual is an isotropic 2-vector of sigma ``s = sigma sqrt(1 + 9 + 9 +
1)`` per component (weights ``3, -3, 1`` of evenly spaced neighbours and the
point's own), so ``P(|r| > t) = exp(-t^2 / (2 s^2))`` on one side and, the
two sides nearly independent, ``P(r_i > t) = exp(-t^2 / s^2)``: the median of
``r_i`` is ``s sqrt(ln 2)``.  The touch's scale ``s`` is the median of its
``r_i`` over ``sqrt(ln 2)`` -- the data's own noise, robust to the outliers
themselves.  A point is set aside when ``r_i`` exceeds ``k s`` with ``k =
sqrt(2 ln(m / ALPHA))`` (``m`` the touch's points): even on one side,
Gaussian noise passes that bound at any of the ``m`` points with
probability below :data:`ALPHA`.  Noise-free data have no noise to scale
by; there a curve still leaves its quadratic prediction by its own shape (a
mesh section's facets, a surface's third derivative), and the bound is never
below :data:`FLOOR` times the touch's median step between points: an
outlier is off the trace by more than a step.  (Sections of the YCB scans,
noise-free, leave their prediction by up to 0.7 of a step at the facets'
corners.)  A set-aside point is gone for every model alike, so every
registration is compared on the same points; the solver's steps and the
errors are the plain ones, on the points kept (a hard-rejecting loss).

The ends.  Where a touch had outliers, so that its sensor slips, the
:data:`ENDS` points at each end of a curve that the spike residual could
not judge are judged against the registration instead: under the best pose
that a search of the judged points alone (each curve without its ends)
finds, so that no end point tilts the pose it is judged by.  (A search of
every point will not do: it may fit an end point off its trace and tilt
its neighbours off instead, at a box's corner for one; nor will a local
refinement of its pose on the judged points, which on a mesh stalls where
the tilted pose lies.)  An end point is off when its distance to the model
under that pose exceeds ``k`` times the touch's noise sigma (third
differences of the points kept) -- the same ``k``: Gaussian noise passes
it with probability below :data:`ALPHA` -- and :data:`FLOOR` steps; it is
set aside too, and the judged search's registrations, every model's, are
refined from their poses on the points left (:func:`tactrec.recognition.again.judge_ends`): those
points are the judged ones and the good ends, which the poses already fit,
so a few steps carry each pose over, at a small part of a second search's
cost.  A judged search that did not settle (its budget ran out before a
fit) has no registrations to carry over: the points left are searched
again.  Two ends are not judged (:func:`judged_ends`): the end a one-sided
curve meets the others at (set aside, it would take the contact from the
judged points' estimate), and both ends of a curve too short to lose them
(under 12 points: it would keep under half).

Where the judged points leave that pose free along a direction that only
the ends hold (the judged points on a box's two faces, an end on the
third), good end points may be set aside with the bad: they cost the fit
points, not its answer.  A touch without outliers is never judged this
way, so that a model the search got wrong, which leaves a clean curve's
ends off, sets nothing aside.

A touch with nothing set aside is used exactly as given.  A touch whose
outliers leave a curve fewer than :data:`~tactrec.io.touch.MIN_POINTS`
points, or fewer than half its points (then the curve is mostly off its
trace, and what it keeps is no trace either), is an
:class:`~tactrec.errors.InputError` naming its file.  Where more than half
of a touch's points are off their traces, their median is an outlier's and
the rule sees no spikes: it is made for a few per cent.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .errors import InputError
from .io.touch import MIN_POINTS, TactileData

__all__ = ["ALPHA", "FLOOR", "ENDS", "spike_residuals", "bound", "flagged", "kept", "ends", "ends_off", "without",
           "judged_ends"]

#: the chance that Gaussian noise sets any point of a touch aside
ALPHA = 1e-6
#: how many points at each end of a curve the spike residual does not judge (one side only)
ENDS = 3
#: the least bound, in median steps between a curve's points: what noise-free curves leave their prediction by
FLOOR = 1.25


def _one_side(x: np.ndarray, step: int, order: int = 2) -> np.ndarray:
    """Residuals ``(n,)`` of each point of ``x (n, 3)`` from the quadratic through its three neighbours on
    one side (``order`` 1: the line through two; ``step`` -1: before it, 1: after it), extrapolated by
    the point's chord to its neighbour, across the extrapolated tangent; NaN without the neighbours."""
    n, need = len(x), order + 1
    out = np.full(n, np.nan)
    if n <= need:
        return out
    i = np.arange(need, n) if step < 0 else np.arange(0, n - need)
    a, b = x[i + step], x[i + 2 * step]
    h1 = np.sqrt(np.sum((a - b) ** 2, axis=1))
    s = np.sqrt(np.sum((x[i] - a) ** 2, axis=1))
    with np.errstate(all="ignore"):
        if order == 1:
            t = (a - b) / h1[:, None]
            p = a + s[:, None] * t
        else:       # Lagrange quadratic through c (at -h1-h2), b (at -h1), a (at 0), at s
            c = x[i + 3 * step]
            h2 = np.sqrt(np.sum((b - c) ** 2, axis=1))
            tb, tc = -h1, -h1 - h2
            la = (s - tb) * (s - tc) / (tb * tc)
            lb, lc = s * (s - tc) / (tb * (tb - tc)), s * (s - tb) / (tc * (tc - tb))
            da, db, dc = (2 * s - tb - tc) / (tb * tc), (2 * s - tc) / (tb * (tb - tc)), (2 * s - tb) / (tc * (tc - tb))
            p = la[:, None] * a + lb[:, None] * b + lc[:, None] * c
            t = da[:, None] * a + db[:, None] * b + dc[:, None] * c
            t = t / np.sqrt(np.sum(t * t, axis=1))[:, None]
        d = x[i] - p
        d = d - np.sum(d * t, axis=1)[:, None] * t
        out[i] = np.sqrt(np.sum(d * d, axis=1))
    return out


def spike_residuals(curve: np.ndarray, order: int = 2) -> np.ndarray:
    """Each point's residual ``r_i`` ``(n,)`` (module text): the smaller of its two sides' (NaN where a
    side lacks the neighbours -- a curve's first and last three points -- or they repeat a point)."""
    x = np.asarray(curve, dtype=np.float64)
    both = np.stack([_one_side(x, -1, order), _one_side(x, 1, order)])
    r = np.minimum(both[0], both[1])
    return np.where(np.isfinite(r), r, np.nan)


def bound(residuals: np.ndarray, step: float) -> float:
    """The bound beyond which a residual is an outlier's (module text), for the touch's residuals
    ``(m,)`` (NaN ignored) and its median step between points."""
    r = residuals[np.isfinite(residuals)]
    if len(r) == 0:
        return np.inf
    k = np.sqrt(2.0 * np.log(len(residuals) / ALPHA))
    scale = float(np.median(r)) / np.sqrt(np.log(2.0))
    return max(k * scale, FLOOR * step)


def flagged(data: TactileData) -> list[np.ndarray]:
    """Per curve, which points are set aside ``(n_i,)`` bool (module text)."""
    curves = [np.asarray(c, dtype=np.float64) for c in data.curves]
    residuals = [spike_residuals(c) for c in curves]
    limit = bound(np.concatenate(residuals), data.spacing)
    return [np.isfinite(r) & (r > limit) for r in residuals]


def kept(data: TactileData) -> tuple[TactileData, int]:
    """``data`` without the points set aside, and how many were (``data`` itself when none was).  An
    :class:`InputError` naming ``data.source`` where a curve keeps fewer than
    :data:`~tactrec.io.touch.MIN_POINTS` points or fewer than half its points."""
    marks = flagged(data)
    count = int(sum(int(m.sum()) for m in marks))
    if count == 0:
        return data, 0
    return without(data, marks, count), count


def without(data: TactileData, marks: list[np.ndarray], count: int) -> TactileData:
    """``data`` without the points ``marks`` (per curve, ``(n_i,)`` bool), ``count`` of which are outliers in
    all (for the message); an :class:`InputError` naming ``data.source`` where a curve keeps fewer than
    :data:`~tactrec.io.touch.MIN_POINTS` points or fewer than half its points."""
    curves = []
    for i, (c, m) in enumerate(zip(data.curves, marks)):
        left = np.asarray(c, dtype=np.float64)[~m]
        if len(left) < max(MIN_POINTS, len(m) / 2):
            raise InputError(f"{count} points are outliers (off their curve's trace): curve {i + 1} keeps "
                             f"{len(left)} of {len(m)} points, at least {MIN_POINTS} and half are needed",
                             data.source)
        curves.append(left)
    return dataclasses.replace(data, curves=tuple(curves))


def ends(sizes) -> list[np.ndarray]:
    """Per curve of ``sizes`` points, which are among the :data:`ENDS` at either end ``(n_i,)`` bool."""
    marks = []
    for n in sizes:
        end = np.zeros(n, dtype=bool)
        end[:ENDS], end[max(n - ENDS, 0):] = True, True
        marks.append(end)
    return marks


def judged_ends(curves, contact: np.ndarray) -> list[np.ndarray]:
    """Per curve of ``curves`` (``(n_i, 3)`` each), which of the :data:`ENDS` points at either end the fit
    judges ``(n_i,)`` bool: each such end, except the end the meeting point ``contact (3,)`` lies at (a
    one-sided curve's: set aside, it would take the contact from the judged points' estimate), and
    no end of a curve that would keep fewer than :data:`~tactrec.io.touch.MIN_POINTS` or half its
    points without both (its ends are kept unjudged)."""
    marks = []
    for c in curves:
        c = np.asarray(c, dtype=np.float64)
        n = len(c)
        end = np.zeros(n, dtype=bool)
        if n - 2 * ENDS >= max(MIN_POINTS, n / 2):
            at = int(np.argmin(np.sum((c - contact) ** 2, axis=1)))
            end[:ENDS], end[n - ENDS:] = at >= ENDS, at < n - ENDS
        marks.append(end)
    return marks


def ends_off(curves, residuals: np.ndarray, noise: float, step: float, judged=None) -> list[np.ndarray]:
    """Per curve of ``curves`` (``(n_i, 3)`` each), which of its judged end points (``judged``, per curve
    ``(n_i,)`` bool; None: the :data:`ENDS` at either end) lie off the registered model (module text):
    ``residuals (sum n_i,)`` their signed distances under the pose of the judged points, ``noise`` the
    touch's sigma and ``step`` its median step between points."""
    sizes = [len(c) for c in curves]
    k = np.sqrt(2.0 * np.log(max(sum(sizes), 1) / ALPHA))
    limit = max(k * noise, FLOOR * step)
    bounds = np.cumsum([0] + sizes)
    judged = ends(sizes) if judged is None else judged
    return [end & (np.abs(residuals[a:b]) > limit) for end, a, b in zip(judged, bounds[:-1], bounds[1:])]
