"""Lines the sensor followed without meeting anything: evidence against the poses they cut through.

A touch whose approach line met nothing (docs/formats.md, ``"missed"``) says the
object's surface does not cross that line.  Under a hypothesis (a model at
its joint pose), the line is sampled every half of the touches' median point
spacing, mapped into the model's frame, and its deepest point inside the
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

from ..probability import CONSISTENT_SE, residuals

__all__ = ["cut_depth", "miss_excess", "first_hit"]


def cut_depth(model, hypothesis, line, step: float) -> float:
    """How far (world units) ``line`` (:class:`~tactrec.io.session.MissedLine`, world frame) cuts into
    ``model`` under ``hypothesis`` (``model = s R world + t``), sampled every ``step``; 0 outside."""
    d = residuals(model, hypothesis.rotation, hypothesis.translation, line.points(step), hypothesis.scale)
    d = d[np.isfinite(d)]                     # a closed-form surface's distance is undefined where its gradient is 0
    return float(max(0.0, -d.min())) if len(d) else 0.0


def miss_excess(models: dict, hypotheses, lines, *, step: float, limit: float) -> np.ndarray:
    """Each hypothesis' excess ``(k, q)`` on each of ``q`` missed ``lines`` (module text): ``models``
    by name, ``step`` the sampling step and ``limit`` the touches' fit limit, world units."""
    out = np.zeros((len(hypotheses), len(lines)))
    for i, h in enumerate(hypotheses):
        for j, line in enumerate(lines):
            out[i, j] = CONSISTENT_SE * cut_depth(models[h.model], h, line, step) / max(limit, 1e-300)
    return out


def first_hit(model, hypothesis, line, step: float) -> np.ndarray | None:
    """Where ``line`` (world frame) first meets ``model``'s surface under ``hypothesis``, world frame:
    the first sample of the line (every ``step``) inside the surface, interpolated linearly in signed
    distance from the sample before; the start where it starts inside; None where it meets nothing."""
    x = line.points(step)
    d = residuals(model, hypothesis.rotation, hypothesis.translation, x, hypothesis.scale)
    inside = np.nonzero(d <= 0.0)[0]
    if len(inside) == 0:
        return None
    i = int(inside[0])
    if i == 0:
        return x[0]
    f = d[i - 1] / (d[i - 1] - d[i])
    return x[i - 1] + f * (x[i] - x[i - 1])
