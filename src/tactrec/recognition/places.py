"""Whether the data tell the answer's place on its model from the other places its search posed there.

A touch may fit two places of one object alike: a patch of a bottle's side fits anywhere along it, a
smooth part of a scan fits other smooth parts within the noise.  The answer's model is then right
while the contact it gives is one of several the data cannot tell apart, and a user who asks *where*
must be told so.  The search keeps the other poses it refined on the answer's model
(:attr:`~tactrec.registration.result.Registration.alternatives`); those whose contact lies beyond
the touch's reach from the answer's (:attr:`~tactrec.features.Touch.radius`: the touch laid on
another place, not the same place a little off, which the contact's ``spread`` covers) are weighed
against the answer's pose as the models are weighed (:mod:`tactrec.probability`: each pose's
distances to the touch's points, resampled): the answer's place's share of the replicates is
:attr:`~tactrec.recognition.result.Recognition.place`, and below
:data:`~tactrec.probability.AMBIGUOUS` the contact is not located.  An alternative was refined
on a part of the points only, so it bounds its place's fit from above: where the others as posed
already fit about as well, the answer is not located; else each takes the exact steps of the
search's final polish on all the points (:func:`place_stage`), which bring its fit closer, and is
weighed again, so that two places alike read alike.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..methods.fast_config import FastConfig
from ..probability import evidence, residuals, resolution
from ..registration.result import Registration
from ..registration.solver import Criteria, solve

__all__ = ["other_places", "place_stage", "place_share"]


def other_places(r: Registration, touch) -> list[Registration]:
    """The poses of ``r.alternatives`` whose contact lies farther from ``r``'s than the touch's radius
    (``touch`` a :class:`~tactrec.features.Touch`; data units), each as a registration of ``r``'s
    model."""
    if r is None or r.alternatives is None or not len(r.alternatives):
        return []
    c = np.asarray(touch.geometry.contact, dtype=np.float64)
    here = np.sum(np.asarray(r.rotation) * c, axis=1)                                # element-wise: no BLAS
    out = []
    for a in np.asarray(r.alternatives, dtype=np.float64):
        moved = (np.sum(a[:, :3] * c, axis=1) - here) + (a[:, 3] - r.translation) / r.scale   # data units
        if float(np.sqrt(np.sum(moved * moved))) > touch.radius:
            out.append(dataclasses.replace(r, rotation=a[:, :3].copy(), translation=a[:, 3].copy(),
                                           alternatives=None))
    return out


def place_share(signed: list[np.ndarray], touch, floor: float) -> float:
    """The answer's place's share of the bootstrap replicates among it and the other places:
    ``signed`` each pose's signed distances to the touch's points (data units), the answer's first;
    1 where there is no other place."""
    if len(signed) < 2:
        return 1.0
    found = evidence([str(k) for k in range(len(signed))], signed, [len(c) for c in touch.joint_curves],
                     touch.noise, resolution=resolution(touch, floor))
    return float(found.shares()[0])


def place_stage(held, indices, touch, found: list[Registration]) -> list[np.ndarray]:
    """A runner's stage: each registration of ``found`` (on the model of ``held`` each index of
    ``indices`` names) refined by the final polish's exact steps on all the touch's points
    (:class:`~tactrec.methods.fast_config.FastConfig`'s ``polish_iterations``, kept where they lower
    the error), and its signed distances to them (data units)."""
    steps = Criteria(FastConfig.polish_iterations, tolerance=FastConfig.tolerance, history=FastConfig.history)
    out = []
    for i, r in zip(indices, found):
        t = touch.in_units(r.scale)
        exact = t.exact(held.entries[i].model)
        R, tr, _, _ = solve(exact, r.rotation[None], r.translation[None], t.joint_points, steps)
        before = residuals(exact, r.rotation, r.translation, touch.joint_points, r.scale)
        after = residuals(exact, R[0], tr[0], touch.joint_points, r.scale)
        out.append(after if np.mean(np.abs(after)) < np.mean(np.abs(before)) else before)
    return out
