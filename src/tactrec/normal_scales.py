"""The data normal at several scales: the tangent cone of the first millimetre up to the fit's window.

The estimate of :mod:`tactrec.estimation` (eq. 1, and the paraboloid fit of
:func:`tactrec.registration.mesh_fast.data_curvatures`) reads the normal
over a window of several millimetres.  On a smooth place that is the
surface's normal; on a sharp, thin or folded place (a crest, a leg a few
millimetres thick, a CAD part's edge) the curves wrap round the feature
within that window and the fit is tens of degrees off.  The finest scale
the points allow still sees the surface: six chords, from the contact to
the point at arc length ``s`` along each half-curve, span its tangent cone,
and the normal of the plane through their unit tips is its axis
(:func:`chord_normal`; on a smooth place, eq. 1 on the chords).  On nine
P3 touches of the bones and the dog of ``--scans other`` where the search
had ended on no fit, eq. 1 was 5-88 degrees off the mesh's normal and the
paraboloid fit 8-113; the finest scale was within 14 degrees on 8 of them.

:func:`cone_normals` gives that normal at arc lengths ``s, 2 s, 4 s, ...``
up to half the median half-curve's length.  The finest ``s`` is one point
step, or where the noise allows: a chord of length ``s`` under noise
``sigma`` per coordinate points about ``sqrt(2) sigma / s`` radians off, so
``s`` is where that is a quarter of the angle two normals must differ by to
pose the data differently (:data:`tactrec.engine.screen.DISTINCT`): two
scales' normals farther apart than that differ by the surface, not the
noise.  A touch whose scales disagree says so itself
(:attr:`Scales.agree`): it lies on a sharp, thin or folded place.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .linalg import eigh, gram, norm3

__all__ = ["Scales", "cone_normals", "chord_normal"]


@dataclasses.dataclass(frozen=True)
class Scales:
    """The data normal at several scales, finest first.

    Attributes
    ----------
    lengths : (k,) arc lengths of the chords, data units
    normals : (k, 3) unit normals, each on the side of the estimate's normal
    distinct : float, degrees: normals farther apart than this pose the data differently
    """

    lengths: np.ndarray
    normals: np.ndarray
    distinct: float

    @property
    def spread(self) -> float:
        """The largest angle between two scales' normals, degrees (0 for one scale)."""
        if len(self.normals) < 2:
            return 0.0
        cos = np.clip(np.sum(self.normals[:, None] * self.normals[None], axis=2), -1.0, 1.0)
        return float(np.degrees(np.arccos(np.min(cos))))

    @property
    def agree(self) -> bool:
        """Whether every scale gives the same normal within :attr:`distinct` degrees."""
        return self.spread <= self.distinct


def _point_at(curve: np.ndarray, i0: int, step: int, length: float) -> np.ndarray | None:
    """The point at arc length ``length`` from ``curve[i0]`` walking by ``step`` (+1 or -1), linearly
    interpolated; None where the curve ends first."""
    arc, i = 0.0, i0
    while 0 <= i + step < len(curve):
        piece = float(norm3(curve[i + step] - curve[i]))
        if arc + piece >= length:
            a = (length - arc) / piece if piece > 0 else 0.0
            return curve[i] + a * (curve[i + step] - curve[i])
        arc, i = arc + piece, i + step
    return None


def chord_normal(chords: np.ndarray, side: np.ndarray) -> np.ndarray:
    """The axis of the cone the chords span, on the side of ``side (3,)``: the normal of the plane
    fitted through the unit chords' tips ``u_i`` (the smallest eigenvector of their scatter about
    their mean).  The tips of a cone's chords lie on a circle about its axis; on a smooth place the
    chords lie in the tangent plane, their mean is about zero, and this is eq. 1 on the chords."""
    u = chords / np.linalg.norm(chords, axis=1, keepdims=True)
    c = u - u.mean(axis=0)
    _, v = eigh(gram(c[None])[0])
    n = v[:, 0]
    return n if float(np.sum(n * side)) >= 0 else -n


def cone_normals(curves, contact: np.ndarray, normal: np.ndarray, *, sigma: float, distinct: float,
                 window: np.ndarray | None = None) -> Scales:
    """The normal of the tangent cone of the six half-curves at arc lengths ``s, 2 s, ...`` (module
    text), oriented like ``normal (3,)``; ``sigma`` the noise per coordinate, ``distinct`` degrees.
    ``window (3,)``: the normal fitted over the estimate's window (eq. 1), appended as the coarsest
    scale (at the longest half-curve's length)."""
    curves = [np.asarray(c, dtype=np.float64) for c in curves]
    contact = np.asarray(contact, dtype=np.float64)
    starts = [int(np.argmin(np.linalg.norm(c - contact, axis=1))) for c in curves]
    steps = np.concatenate([np.linalg.norm(np.diff(c, axis=0), axis=1) for c in curves])
    spacing = float(np.median(steps)) if len(steps) else 0.0
    halves = []
    for c, i0 in zip(curves, starts):
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
        halves += [(c, i0, -1, arc[i0]), (c, i0, 1, arc[-1] - arc[i0])]
    reach = sorted(h[3] for h in halves if h[3] > 0)
    finest = max(spacing, np.sqrt(2.0) * sigma / (0.25 * np.deg2rad(distinct)))
    lengths, normals = [], []
    longest = 0.5 * reach[len(reach) // 2] if reach else 0.0        # half the median half-curve's length
    s = finest
    while s <= longest + 1e-12:
        chords = []
        for c, i0, step, _ in halves:
            p = _point_at(c, i0, step, s)
            if p is not None:
                chords.append(p - c[i0])
        if len(chords) >= 3:
            lengths.append(s)
            normals.append(chord_normal(np.array(chords), normal))
        s *= 2.0
    if window is not None:
        w = np.asarray(window, dtype=np.float64)
        lengths.append(reach[-1] if reach else 0.0)
        normals.append(w if float(np.sum(w * normal)) >= 0 else -w)
    if not normals:
        return Scales(np.zeros(0), np.zeros((0, 3)), float(distinct))
    return Scales(np.array(lengths), np.array(normals), float(distinct))
