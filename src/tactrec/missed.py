"""Lines the sensor followed without meeting anything: evidence against the poses they cut through.

A touch whose approach line met nothing (docs/formats.md, ``"missed"``) says the
object's surface does not cross that line.  Under a hypothesis (a model at
its joint pose), the line is sampled every half of the touches' median point
spacing (single contacts have none: :func:`line_step`), mapped into the
model's frame, and its deepest point inside the
model (the most negative signed distance) is how far the line cuts into the
surface.  That depth, against the fit limit of the touches the pose was
fitted to (the points-weighted mean of their
:func:`~tactrec.probability.fit_limit`), is the line's excess in the fit
test's units: ``CONSISTENT_SE x depth / limit``, so a line that cuts in by
as much as a fit may miss the surface is at the test's edge, and one that
stays outside has none (:class:`~tactrec.probability.Evidence`, ``misses``).
The joint pose is not searched again for a line: a model whose pose a line
cuts through loses its probability, and the next touch's search may find it
another pose.
"""

from __future__ import annotations

import numpy as np

from .probability import CONSISTENT_SE, residuals

__all__ = ["crossing", "cut_depth", "depth_excess", "miss_excess", "first_hit", "line_step", "SAMPLES"]

#: points a line is sampled at where the touches have no point spacing to sample it by (single contacts)
SAMPLES = 400


def line_step(spacing: float, length: float) -> float:
    """The step a line ``length`` long is sampled at for touches whose points lie ``spacing`` apart: that,
    or where they have none (a session of single contacts), ``length / SAMPLES``."""
    return float(spacing) if spacing > 0 else float(length) / SAMPLES


def crossing(model, hypothesis, line, step: float) -> tuple[np.ndarray | None, float]:
    """Where ``line`` (:class:`~tactrec.io.session.MissedLine`, world frame) first meets ``model``'s
    surface under ``hypothesis`` (``model = s R world + t``) and how far it cuts into it, from one
    pass over the line sampled every ``step``: ``(hit, depth)``.  ``hit`` (world frame) is the first
    sample inside the surface, interpolated linearly in signed distance from the sample before (the
    start where it starts inside; None where it meets nothing); ``depth`` (world units) is how far
    the deepest sample lies inside, 0 outside."""
    x = line.points(step)
    d = residuals(model, hypothesis.rotation, hypothesis.translation, x, hypothesis.scale)
    finite = d[np.isfinite(d)]                # a closed-form surface's distance is undefined where its gradient is 0
    depth = float(max(0.0, -finite.min())) if len(finite) else 0.0
    inside = np.nonzero(d <= 0.0)[0]
    if len(inside) == 0:
        return None, depth
    i = int(inside[0])
    if i == 0:
        return x[0], depth
    f = d[i - 1] / (d[i - 1] - d[i])
    return x[i - 1] + f * (x[i] - x[i - 1]), depth


def cut_depth(model, hypothesis, line, step: float) -> float:
    """How far (world units) ``line`` cuts into ``model`` under ``hypothesis`` (:func:`crossing`)."""
    return crossing(model, hypothesis, line, step)[1]


def depth_excess(depth, limit: float):
    """A cut ``depth`` (world units) in the fit test's units (module text), against the touches' fit
    ``limit``."""
    return CONSISTENT_SE * np.asarray(depth, dtype=np.float64) / max(limit, 1e-300)


def miss_excess(models: dict, hypotheses, lines, *, step: float, limit: float) -> np.ndarray:
    """Each hypothesis' excess ``(k, q)`` on each of ``q`` missed ``lines`` (module text): ``models``
    by name, ``step`` the sampling step and ``limit`` the touches' fit limit, world units."""
    return depth_excess([[cut_depth(models[h.model], h, line, step) for line in lines] for h in hypotheses],
                        limit).reshape(len(hypotheses), len(lines))


def first_hit(model, hypothesis, line, step: float) -> np.ndarray | None:
    """Where ``line`` (world frame) first meets ``model``'s surface under ``hypothesis``, world frame
    (:func:`crossing`), or None where it meets nothing."""
    return crossing(model, hypothesis, line, step)[0]
