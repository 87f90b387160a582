"""How a real sensor records a touch: the imperfections a simulated touch can carry.

A simulated touch (:func:`tactrec.simulation.simulate_touch`) is by default an
exact plane section of the model, evenly sampled.  A robot's sensor records
something else, and :class:`Imperfections` describes what, each part on its
own scale and all of them seeded with the touch's ``rng``:

``miss``
    the strokes pass near the contact rather than through it: each curve is
    the plane section through a surface point ``miss`` from the contact,
    across its own direction (to a random side), so the curves miss each
    other by up to about ``2 miss`` while each stays on the surface;
``bend``
    a stroke leaves its plane: each point is pushed across the plane by
    ``bend (s / s_end)^3`` (``s`` its arc length from the contact: an S,
    each end to its own side, its sign random per curve) and put back on
    the surface (closest points).  Its ends then lie about ``0.4 bend`` from
    the curve's best plane (a push even in ``s`` would only tilt the plane);
``uneven``
    points sampled in time while the speed varies: the steps between
    neighbouring points are uniform between ``a`` and ``uneven x a``, their
    mean the touch's spacing (1: even steps, the default), each curve
    keeping its length about the contact;
``tip_radius``
    the points are the centres of a spherical tip of that radius: each
    stroke is the section of the surface offset by the radius with the
    stroke's plane, sampled at the surface points' own steps along it
    (:func:`tip_centres`: every point lies at the radius from the surface;
    in a hollow tighter than the tip it touches the surface elsewhere, and
    over a convex edge the centre sweeps an arc about it);
``jitter``
    Gaussian noise of that sigma on every coordinate, on top of the
    simulation's own ``noise``;
``outliers``
    that share of the points (rounded) moved in a random direction by a
    distance uniform in ``outlier_size`` (slips and spikes).

Lengths are in the model's units.  The truth of a simulated touch records
the imperfections and which points were made outliers.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .io.touch import MIN_POINTS
from .linalg import eigh, gram, norm3
from .tip import Offset

__all__ = ["Imperfections", "record", "tip_centres"]

#: a curve is sampled this many times more finely than the touch's spacing before it is resampled
FINE = 4


@dataclasses.dataclass(frozen=True)
class Imperfections:
    """What a sensor does to a touch (module text); the defaults record it perfectly.

    Attributes
    ----------
    tip_radius : float
        Radius of the spherical tip whose centres are recorded, model units.
    uneven : float
        Ratio of the longest to the shortest step between neighbouring points (>= 1).
    jitter : float
        Gaussian sigma per coordinate, model units.
    outliers : float
        Share of the points moved off the trace, in ``[0, 0.5)``.
    outlier_size : (float, float)
        Least and largest distance an outlier is moved, model units.
    miss : float
        How far each curve's plane passes from the contact, model units.
    bend : float
        How far a stroke leaves its plane at its ends, model units.
    """

    tip_radius: float = 0.0
    uneven: float = 1.0
    jitter: float = 0.0
    outliers: float = 0.0
    outlier_size: tuple = (0.5, 3.0)
    miss: float = 0.0
    bend: float = 0.0

    def __post_init__(self):
        for name in ("tip_radius", "jitter", "miss", "bend"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a non-negative number, not {value!r}")
        if not (np.isfinite(self.uneven) and self.uneven >= 1.0):
            raise ValueError(f"uneven is the ratio of the longest step to the shortest: at least 1, not {self.uneven!r}")
        if not (0.0 <= self.outliers < 0.5):
            raise ValueError(f"outliers is a share of the points in [0, 0.5), not {self.outliers!r}")
        lo, hi = (float(x) for x in self.outlier_size)
        if not (np.isfinite(hi) and 0.0 <= lo <= hi):
            raise ValueError(f"outlier_size must be two distances, least first, not {self.outlier_size!r}")
        object.__setattr__(self, "outlier_size", (lo, hi))

    @property
    def perfect(self) -> bool:
        """Whether nothing is done to the touch."""
        return self == Imperfections(outlier_size=self.outlier_size)

    def to_json(self) -> dict:
        return dataclasses.asdict(self) | {"outlier_size": list(self.outlier_size)}


def _resampled(curve: np.ndarray, centre: int, spacing: float, ratio: float, rng) -> np.ndarray:
    """Points along the polyline ``curve (n, 3)`` at steps uniform in ``[a, ratio a]`` (mean ``spacing``)
    from its point ``centre`` outwards both ways, up to its ends."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
    arc = arc - arc[centre]
    a = 2.0 * spacing / (1.0 + ratio)
    sides = []
    for end in (arc[-1], -arc[0]):
        steps = rng.uniform(a, ratio * a, size=int(np.ceil(end / a)) + 1)
        s = np.cumsum(steps)
        sides.append(s[s <= end + 1e-12 * max(end, 1.0)])
    s = np.concatenate([-sides[1][::-1], [0.0], sides[0]])
    return np.stack([np.interp(s, arc, curve[:, j]) for j in range(3)], axis=1)


def record(model, frame, tangents: np.ndarray, *, spacing: float, points: int, imperfections: Imperfections,
           rng) -> tuple[list, dict]:
    """The curves ``(n_i, 3)`` a sensor records along ``tangents (k, 3)`` at the site ``frame`` of
    ``model`` (a :class:`~tactrec.surfaces.base.SiteFrame`), model frame, with ``imperfections``
    (module text), and what was done (``{"outlier_points": [[curve, index], ...], ...}``).

    Without ``uneven`` the curves have ``points`` points ``spacing`` apart as a perfect touch's.
    To bend or resample a curve its section is taken :data:`FINE` times more finely (resampled
    points are put back on the surface).  Raises ``ValueError``
    where a section leaves the surface."""
    imp = imperfections
    fine = FINE if imp.uneven > 1.0 or imp.bend > 0 else 1               # finer only to resample or bend
    fine_count = (points - 1) * fine + 1
    centre = (fine_count - 1) // 2
    if imp.miss == 0 and hasattr(model, "plane_sections"):
        sections = list(model.plane_sections(frame.site, tangents, spacing=spacing / fine, count=fine_count))
        sites = [frame.site] * len(tangents)
    else:
        sections, sites = [], []
        for tangent in tangents:
            site = frame.site
            if imp.miss > 0:
                across = np.cross(frame.normal, tangent)
                across = across / norm3(across) * rng.choice((-1.0, 1.0))
                site = model.locate(frame.point + imp.miss * across)
            sections.append(model.plane_section(site, tangent, spacing=spacing / fine, count=fine_count))
            sites.append(site)
    curves = []
    for tangent, site, curve in zip(tangents, sites, sections):
        if imp.bend > 0:
            normal = model.site_frame(site).normal
            side = np.cross(tangent, normal)
            side = side / norm3(side) * rng.choice((-1.0, 1.0))
            s = (np.arange(fine_count) - centre) / centre
            curve = model.projected(curve + imp.bend * (s * s * s)[:, None] * side)
        if imp.uneven > 1.0:
            curve = model.projected(_resampled(curve, centre, spacing, imp.uneven, rng))
            if len(curve) < MIN_POINTS:
                raise ValueError(f"uneven steps left a curve {len(curve)} points: ask for more points")
        else:
            curve = curve[::fine]
        if imp.tip_radius > 0:
            across = np.cross(tangent, model.site_frame(site).normal)          # the stroke's plane
            curve = tip_centres(model, curve, imp.tip_radius, across=across, anchor=frame.point)
            if len(curve) < MIN_POINTS:
                raise ValueError(f"a {imp.tip_radius:g} tip's path left a curve {len(curve)} points")
        curves.append(curve)
    if imp.jitter > 0:
        curves = [c + rng.normal(0.0, imp.jitter, size=c.shape) for c in curves]
    moved = []
    total = sum(len(c) for c in curves)
    count = int(round(imp.outliers * total))
    if count:
        which = np.sort(rng.choice(total, size=count, replace=False))
        bounds = np.cumsum([0] + [len(c) for c in curves])
        direction = rng.normal(size=(count, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        size = rng.uniform(*imp.outlier_size, size=count)
        for j, d, r in zip(which, direction, size):
            i = int(np.searchsorted(bounds, j, side="right") - 1)
            curves[i][j - bounds[i]] += r * d
            moved.append([i, int(j - bounds[i])])
    return curves, {"outlier_points": moved}


def _pushed_out(model, centres: np.ndarray, radius: float, across: np.ndarray,
                iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """``centres (n, 3)`` moved within the plane of normal ``across (3,)`` (unit), each along its closest
    point's normal as that plane holds it, until each is at ``radius`` from the surface (within 1e-9
    of it, or after ``iterations`` moves); and how far each then is from that ``(n,)``."""
    offset = Offset(model, radius)                   # exact distances (a closed form's to its foot points)
    for k in range(iterations + 1):
        d, n = offset.planes(centres)
        short = -np.asarray(d, dtype=np.float64)
        if k == iterations or not np.any(np.abs(short) > 1e-9 * max(radius, 1.0)):
            break
        u = np.asarray(n, dtype=np.float64)
        u = u - np.sum(u * across[None], axis=1)[:, None] * across[None]       # element-wise: no BLAS
        held = np.sum(u * u, axis=1)                     # how much of the distance a move along u changes
        centres = centres + np.where(held > 1e-6, short / np.maximum(held, 1e-6), 0.0)[:, None] * u
    return centres, np.abs(short)


def _arc_length(x: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])


def tip_centres(model, points: np.ndarray, radius: float, *, across: np.ndarray | None = None,
                anchor: np.ndarray | None = None, iterations: int = 200) -> np.ndarray:
    """The centres ``(n, 3)`` of a spherical tip of ``radius`` traced along the surface points ``points
    (n, 3)`` of a stroke, as a sensor records them: the section of the surface offset by ``radius``
    with the stroke's plane (of unit normal ``across``; default: the plane through the points' mean
    spanned by their main direction and the surface's normal at the middle point), sampled at the
    points' own steps along it.

    Each point is pushed out within that plane until it lies at ``radius`` from the surface; the
    path is filled in (each step cut into pieces of an eighth of the shortest step, each pushed out
    alike: over a convex edge the arc the centre sweeps about it, in a hollow tighter than the tip
    the place where it touches both sides) and sampled again at the surface points' own steps along
    it, from the point nearest ``anchor`` (default: the middle point).  A tip there touches the
    surface at its closest point and enters it nowhere.  A ``ValueError`` where the plane holds no
    such centre near a point (a hollow too narrow for the tip in that plane): no tip traces that
    stroke."""
    x = np.asarray(points, dtype=np.float64)
    if across is None:
        along = eigh(gram((x - x.mean(axis=0))[None])[0])[1][:, 2]              # the points' main axis
        across = np.cross(along, np.asarray(model.planes(x[len(x) // 2][None])[1], dtype=np.float64)[0])
    across = np.asarray(across, dtype=np.float64) / norm3(across)
    centres, _ = _pushed_out(model, x, radius, across, iterations)
    steps = np.linalg.norm(np.diff(x, axis=0), axis=1)
    piece = float(steps[steps > 0].min(initial=np.inf)) / 8.0
    if not np.isfinite(piece):
        raise ValueError("a stroke whose points are all one point")
    cuts = np.maximum(np.ceil(np.linalg.norm(np.diff(centres, axis=0), axis=1) / piece).astype(int), 1)
    filled = [centres[:1]]
    for i, k in enumerate(cuts):
        w = (np.arange(1, k + 1) / k)[:, None]
        filled.append(centres[i] + w * (centres[i + 1] - centres[i]))
    start = np.concatenate([[0], np.cumsum(cuts)])                    # where each centre lies in the fill
    dense, _ = _pushed_out(model, np.concatenate(filled), radius, across, iterations)
    s = _arc_length(dense)
    k = len(x) // 2 if anchor is None else int(np.argmin(np.linalg.norm(x - anchor, axis=1)))
    want = s[start[k]] + (_arc_length(x) - _arc_length(x)[k])
    inside = (want >= s[0]) & (want <= s[-1])
    out, gap = _pushed_out(model, np.stack([np.interp(want[inside], s, dense[:, j]) for j in range(3)], axis=1),
                           radius, across, iterations)
    if np.any(gap > 1e-6 * max(radius, 1.0)):
        raise ValueError(f"a tip of radius {radius:g} cannot follow this stroke in its plane (a hollow too "
                         "narrow for it)")
    return out
