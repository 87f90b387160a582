"""Simulated touches (paper Sections 4.3 and 5.4).

``k`` sampling planes through the contact point, each containing the surface
normal there, adjacent planes ``angle`` apart; points at equal arc-length
spacing centred on the contact; uniform (``+/- noise``) or Gaussian (sigma
``noise``) noise on every coordinate; then a random rigid motion, since a
sensor never reports in the model's frame.  The truth (site, contact, normal
and the data-to-model pose) is kept in ``data.meta["truth"]``.  A touch as a
real sensor records it (a round tip, uneven steps, jitter, outliers, strokes
that miss the contact or bend out of their plane) takes
:class:`tactrec.sensor.Imperfections`.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from .errors import InputError
from .io.touch import TactileData
from .linalg import compose, dot3, rotate, tangents, times
from .sensor import Imperfections, record
from .surfaces.base import SurfaceModel

__all__ = ["simulate_touch", "simulate_random_touch", "random_rigid_motion", "spread_vertices", "sensor_to_world",
           "truth_pose", "truth_contact",
           "simulate_world_touch", "simulate_patch", "simulate_contacts", "perturbed", "PATCH_POINTS"]

#: the pixels a simulated patch holds by default (its pitch follows from its radius)
PATCH_POINTS = 400
#: the most a model's signed distance changes per unit along a ray (a distance's 1, a trilinear field's
#: reading up to sqrt(3), rounded up)
LIPSCHITZ = 2.0


def random_rigid_motion(rng, *, extent: float) -> tuple[np.ndarray, np.ndarray]:
    """A uniformly random rotation and a translation uniform in ``[-extent, extent]^3``."""
    rng = np.random.default_rng(rng)
    R = Rotation.random(random_state=rng).as_matrix()
    t = rng.uniform(-extent, extent, size=3)
    return R, t


def simulate_touch(model: SurfaceModel, site, *, points: int = 61, spacing: float, angle: float = 60.0,
                   curves: int = 3, noise: float = 0.0, noise_kind: str = "uniform",
                   first_direction: float | None = None, outward: bool = True, contact: bool = False,
                   sensor_frame: bool = True, units: str | None = None, imperfections: Imperfections | None = None,
                   rng=None) -> TactileData:
    """Simulate one touch at ``site`` of ``model``.

    Parameters
    ----------
    model : SurfaceModel
    site : array
        Where the curves meet: ``(u, v)`` on a closed-form surface.
    points : int
        Points per curve (odd: the contact is the middle point).
    spacing : float
        Arc length between neighbouring points, model units.
    angle : float
        Degrees between adjacent sampling planes.
    curves : int
        Number of curves (>= 3).
    noise : float
        Uniform half-width, or Gaussian sigma, added to every coordinate.
    noise_kind : ``"uniform"`` or ``"gaussian"``
    first_direction : float, optional
        Angle (radians) of the first plane's tangent from the site's ``d1``;
        random by default.
    outward : bool
        Include the outward direction (the side the sensor was on).
    contact : bool
        Include the (noise-free) contact point.
    sensor_frame : bool
        Apply a random rigid motion (default); ``False`` keeps the model frame.
    imperfections : Imperfections, optional
        What the sensor does to the touch (:mod:`tactrec.sensor`); the file then carries the tip
        radius, and the truth the imperfections and the outliers' points.
    rng : seed or Generator
    """
    rng = np.random.default_rng(rng)
    if curves < 3:
        raise ValueError("a touch needs at least 3 curves")
    if points < 5:
        raise ValueError("a curve needs at least 5 points")
    if noise_kind not in {"uniform", "gaussian"}:
        raise ValueError(f"unknown noise kind {noise_kind!r}")
    frame = model.site_frame(site)
    start = rng.uniform(0.0, 2 * np.pi) if first_direction is None else float(first_direction)
    angles = start + np.deg2rad(angle) * np.arange(curves)
    tangents = np.cos(angles)[:, None] * frame.d1 + np.sin(angles)[:, None] * frame.d2
    imperfect = imperfections is not None and not imperfections.perfect
    if imperfect:
        sections, done = record(model, frame, tangents, spacing=spacing, points=points, imperfections=imperfections,
                                rng=rng)
    elif hasattr(model, "plane_sections"):
        sections = list(model.plane_sections(frame.site, tangents, spacing=spacing, count=points))
    else:
        sections = [model.plane_section(frame.site, t, spacing=spacing, count=points) for t in tangents]
    if noise > 0:
        if noise_kind == "uniform":
            sections = [c + rng.uniform(-noise, noise, size=c.shape) for c in sections]
        else:
            sections = [c + rng.normal(0.0, noise, size=c.shape) for c in sections]
    truth = {
        "model": model.name,
        "site": np.asarray(frame.site, dtype=float).tolist(),
        "contact": frame.point.tolist(),
        "normal": frame.normal.tolist(),
    }
    tip = imperfections.tip_radius if imperfect else 0.0
    data = TactileData.from_arrays(sections, contact=frame.point + tip * frame.normal if contact else None,
                                   outward=frame.normal if outward else None, units=units or model.units,
                                   tip_radius=tip, source=f"<simulated {model.name}>")
    if sensor_frame:
        R, t = random_rigid_motion(rng, extent=model.size)
        data = data.transformed(R, t)
        truth["rotation"] = R.T.tolist()            # data -> model
        truth["translation"] = (-rotate(R.T, t)).tolist()
    else:
        truth["rotation"] = np.eye(3).tolist()
        truth["translation"] = [0.0, 0.0, 0.0]
    truth.update(points=points if not imperfect else [len(c) for c in sections], spacing=spacing, angle=angle,
                 noise=noise, noise_kind=noise_kind)
    if imperfect:
        truth["imperfections"] = imperfections.to_json() | done
    meta = {"truth": truth}
    return TactileData.from_arrays(list(data.curves), contact=data.contact, outward=data.outward,
                                   units=data.units, meta=meta, source=f"<simulated {model.name}>",
                                   tip_radius=data.tip_radius)


def simulate_random_touch(model: SurfaceModel, *, rng=None, attempts: int = 200, margin: float = 0.0,
                          vertices: bool = False, maker=None, **options) -> TactileData:
    """A touch at a random site whose curves all stay on the surface (``vertices``: at a random vertex
    of a mesh, where a machined part's edges and corners are); ``maker``, the function that makes the
    touch at a site (:func:`simulate_touch`; :func:`simulate_patch` for a patch)."""
    maker = simulate_touch if maker is None else maker
    rng = np.random.default_rng(rng)
    last = None
    for _ in range(attempts):
        if vertices and hasattr(model, "vertices"):
            site = [int(rng.integers(len(model.vertices)))]
        elif hasattr(model, "random_sites") and margin:
            site = model.random_sites(1, rng=rng, margin=margin)[0]
        else:
            site = model.random_sites(1, rng=rng)[0]
        try:
            return maker(model, site, rng=rng, **options)
        except InputError:
            raise                                          # data no place could make valid: not the site's fault
        except ValueError as exc:
            last = exc
    raise ValueError(f"no touch on {model.name} stayed on the surface in {attempts} attempts ({last})")


def spread_vertices(model, count: int, *, rings: int = 15, rng=None) -> np.ndarray:
    """``count`` random vertices of a mesh, no two within ``rings`` rings (protocol P3).

    Vertices are drawn in a random order and kept when no kept vertex lies in
    their ``rings``-ring; fewer than ``count`` come back if the mesh runs out.
    """
    rng = np.random.default_rng(rng)
    blocked = np.zeros(len(model.vertices), dtype=bool)
    chosen = []
    for v in rng.permutation(len(model.vertices)):
        if len(chosen) == count:
            break
        if blocked[v]:
            continue
        chosen.append(int(v))
        blocked[model.ring(int(v), rings)] = True
    return np.array(chosen, dtype=np.int64)


def truth_pose(data: TactileData) -> tuple[np.ndarray, np.ndarray]:
    """The data-to-model pose ``R (3, 3), t (3,)`` of a simulated touch (``model = R data + t``), from
    its ``meta["truth"]``."""
    truth = data.meta["truth"]
    return np.asarray(truth["rotation"], dtype=np.float64), np.asarray(truth["translation"], dtype=np.float64)


def truth_contact(data: TactileData) -> np.ndarray:
    """The true contact ``(3,)`` of a simulated touch in the data's own frame."""
    R, t = truth_pose(data)
    return rotate(R.T, np.asarray(data.meta["truth"]["contact"], dtype=np.float64) - t)


def sensor_to_world(data: TactileData, model2world) -> tuple[np.ndarray, np.ndarray]:
    """The ``sensor2world`` pose of a simulated touch (its ``meta["truth"]`` data-to-model pose)
    when the object sits in the world at ``model2world = (R, t)`` (``world = R @ model + t``)."""
    truth = data.meta["truth"]
    Rd, td = np.asarray(truth["rotation"], dtype=np.float64), np.asarray(truth["translation"], dtype=np.float64)
    Rw, tw = (np.asarray(a, dtype=np.float64) for a in model2world)
    return compose(Rw, Rd), rotate(Rw, td) + tw


def simulate_world_touch(model: SurfaceModel, world2model, contact, directions, *, points: int, spacing: float,
                         noise: float = 0.0, noise_kind: str = "gaussian", outward: bool = True,
                         sensor_frame: bool = True, rng=None):
    """A touch of ``model`` placed in a world by ``world2model = (R, t, scale)`` (``model = scale R
    world + t``): at the surface point nearest the world point ``contact``, the curves along the
    world ``directions (2+, 3)`` (the first gives the first curve, the second the turn to the
    next), ``spacing`` in world units.  Returns the data and its ``sensor2world`` pose (the data in
    a random sensor frame, or in the world with the identity pose when ``sensor_frame`` is false).
    Raises ``ValueError`` where a curve leaves the surface."""
    R, t, s = np.asarray(world2model[0], dtype=np.float64), np.asarray(world2model[1], dtype=np.float64), \
        float(world2model[2])
    site = model.locate(s * times(contact, R.T) + t)
    frame = model.site_frame(site)
    u, v = times(np.asarray(directions, dtype=np.float64)[:2], R.T)                    # model frame
    first = float(np.arctan2(dot3(u, frame.d2), dot3(u, frame.d1)))
    angle = float(np.degrees((np.arctan2(dot3(v, frame.d2), dot3(v, frame.d1)) - first) % (2 * np.pi)))
    rng = np.random.default_rng(rng)
    data = simulate_touch(model, site, points=points, spacing=spacing * s, angle=angle, first_direction=first,
                          noise=noise * s, noise_kind=noise_kind, outward=outward, sensor_frame=sensor_frame, rng=rng)
    truth = data.meta["truth"]
    Rd, td = np.asarray(truth["rotation"]), np.asarray(truth["translation"])          # data -> model
    # world = R^T (model - t) / s = R^T (Rd data + td - t) / s
    R_sw = compose(R.T, Rd)
    t_sw = rotate(R.T, td - t) / s
    world = data.transformed(np.eye(3), np.zeros(3), scale=1.0 / s)
    return dataclasses.replace(world, meta=data.meta, source=data.source), (R_sw, t_sw)


def _first_hits(model, origins: np.ndarray, direction: np.ndarray, length: float, step: float) -> np.ndarray:
    """How far each ray ``origins (m, 3) + t direction`` runs to its first crossing into the model
    (its signed distance, :meth:`~tactrec.surfaces.base.SurfaceModel.planes`, turning from positive to
    not), within ``length``: stepped every ``step``, then bisected; NaN where it never crosses or
    starts inside.  A distance changes by at most the step between two samples a step apart (it is
    1-Lipschitz; :data:`LIPSCHITZ` allows for a sampled field's reading): a larger jump across zero is
    no surface but a sign the model leaves unsure far from it (a mesh's, signed by its nearest face
    beside a concave edge), and the ray goes on through it."""
    t = np.arange(0.0, length + step, step)
    values = np.stack([model.planes(origins + ti * direction)[0] for ti in t], axis=1)     # (m, len(t))
    crossing = (values[:, :-1] > 0) & (values[:, 1:] <= 0) & (values[:, :-1] - values[:, 1:] <= LIPSCHITZ * step)
    first = np.argmax(crossing, axis=1) + 1
    ok = crossing.any(axis=1) & (values[:, 0] > 0)
    lo, hi = np.where(ok, t[first - 1], np.nan), np.where(ok, t[first], np.nan)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        out = np.zeros(len(mid), dtype=bool)
        out[ok] = model.planes(origins[ok] + mid[ok, None] * direction)[0] > 0
        lo, hi = np.where(out, mid, lo), np.where(out, hi, mid)
    return 0.5 * (lo + hi)


def simulate_patch(model: SurfaceModel, site, *, radius: float, pitch: float | None = None, noise: float = 0.0,
                   blur: float = 0.0, depth: float | None = None, sensor_frame: bool = True,
                   units: str | None = None, stated: bool = False, rng=None) -> TactileData:
    """A patch at ``site`` of ``model`` as a vision-based skin records it: a depth map over the
    tangent plane at the site (its x axis turned at random about the normal), ``pitch`` apart
    (default: about :data:`PATCH_POINTS` pixels in the disc), over a disc of ``radius``; each pixel
    the depth along the sensor's -z to the first surface it meets, null where none lies within
    ``depth`` below the plane (default ``radius``) or the pixel is beyond the disc; the gel's
    smoothing a Gaussian of sigma ``blur`` (model units, over the pixels seen), then Gaussian depth
    noise of sigma ``noise``, which the map states (``point_sd``) where ``stated``.  In a random sensor
    frame unless ``sensor_frame`` is false; the truth as :func:`simulate_touch`'s."""
    from scipy.ndimage import gaussian_filter

    from .io.patch import MAX_HOLES, parse_patch

    rng = np.random.default_rng(rng)
    pitch = float(pitch) if pitch is not None else radius * np.sqrt(np.pi / PATCH_POINTS)
    depth = radius if depth is None else float(depth)
    frame = model.site_frame(site)
    turn = rng.uniform(0.0, 2 * np.pi)
    e1 = np.cos(turn) * frame.d1 + np.sin(turn) * frame.d2
    n = frame.normal
    F = np.column_stack([e1, np.cross(n, e1), n])                   # map -> model
    half = int(np.floor(radius / pitch))
    axis = np.arange(-half, half + 1) * pitch
    y, x = np.meshgrid(axis, axis, indexing="ij")
    disc = (x * x + y * y <= radius * radius).ravel()
    above = radius                                                  # rays start this far above the plane
    origins = frame.point + times(np.column_stack([x.ravel(), y.ravel(), np.full(x.size, above)])[disc], F.T)
    t = _first_hits(model, origins, -n, above + depth, pitch / 2)
    height = np.full(x.size, np.nan)
    height[disc] = t - above
    height[height > depth] = np.nan
    height = height.reshape(x.shape)
    seen = np.isfinite(height)
    if not seen[half, half] or seen.mean() < 1.0 - MAX_HOLES:
        raise ValueError(f"the patch sees too little surface ({100 * seen.mean():.0f}% of its pixels)")
    if blur > 0:
        sigma = blur / pitch
        weight = gaussian_filter(seen.astype(np.float64), sigma, mode="constant")
        smooth = gaussian_filter(np.where(seen, height, 0.0), sigma, mode="constant")
        height = np.where(seen, smooth / np.maximum(weight, 1e-12), np.nan)
    if noise > 0:
        height = height + rng.normal(0.0, noise, size=height.shape)
    R, t_ = (random_rigid_motion(rng, extent=model.size) if sensor_frame else (np.eye(3), np.zeros(3)))
    sensor = {"rotation": compose(R, F).tolist(), "translation": (rotate(R, frame.point) + t_).tolist()}
    obj = {"height": [[None if not np.isfinite(d) else float(d) for d in row] for row in height], "pitch": pitch,
           "sensor": sensor, **({"point_sd": float(noise)} if stated else {})}
    source = f"<simulated {model.name}>"
    truth = {"model": model.name, "site": np.asarray(frame.site, dtype=float).tolist(),
             "contact": frame.point.tolist(), "normal": n.tolist(),
             "rotation": R.T.tolist(), "translation": (-rotate(R.T, t_)).tolist(),
             "patch": {"radius": radius, "pitch": pitch, "noise": noise, "blur": blur, "depth": depth}}
    return TactileData.from_patch(parse_patch(obj, source), units=units or model.units, meta={"truth": truth},
                                  source=source)


def perturbed(points: np.ndarray, normals: np.ndarray, *, noise: float, normal_sd: float, rng):
    """Contacts at ``points (n, 3)`` with outward unit ``normals (n, 3)`` as a sensor records them: Gaussian
    noise of sigma ``noise`` on every coordinate, each normal tilted by a Gaussian of ``normal_sd``
    degrees per tangent direction.  Returns ``(points, normals)``."""
    seen = points + rng.normal(0.0, noise, size=points.shape) if noise > 0 else points
    tilt = normals.copy()
    if normal_sd > 0:
        d1, d2 = tangents(normals)
        a, b = (np.tan(np.deg2rad(rng.normal(0.0, normal_sd, size=len(points))))[:, None] for _ in range(2))
        tilt = normals + a * d1 + b * d2
        tilt /= np.linalg.norm(tilt, axis=1, keepdims=True)
    return seen, tilt


def simulate_contacts(model: SurfaceModel, count: int, *, noise: float = 0.0, normal_sd: float = 0.0,
                      sensor_frame: bool = True, units: str | None = None, rng=None) -> TactileData:
    """``count`` single contacts spread over ``model``: on a mesh, points uniform over its area (the
    faces chosen by area) with their faces' normals; on a closed-form surface, random sites with their
    normals.  Gaussian noise of sigma ``noise`` on every coordinate (stated as each contact's
    ``point_sd`` when > 0); each normal tilted by a Gaussian of ``normal_sd`` degrees per tangent
    direction (stated as its ``normal_sd_deg`` when > 0).  In a random sensor frame unless
    ``sensor_frame`` is false; the truth as :func:`simulate_touch`'s, with every true contact."""
    from .io.contacts import parse_contacts
    from .surfaces.mesh_table import area_samples

    if not (isinstance(count, (int, np.integer)) and count >= 1):
        raise ValueError(f"count must be a whole number >= 1, got {count!r}")
    rng = np.random.default_rng(rng)
    if model.kind == "mesh":
        points, normals = area_samples(model, count, rng)
    else:
        points, normals = model.site_points(model.random_sites(count, rng=rng))
    seen, tilt = perturbed(points, normals, noise=noise, normal_sd=normal_sd, rng=rng)
    R, t = (random_rigid_motion(rng, extent=model.size) if sensor_frame else (np.eye(3), np.zeros(3)))
    items = []
    for p, n in zip(times(seen, R.T) + t, times(tilt, R.T)):
        item = {"point": p.tolist(), "normal": n.tolist()}
        if normal_sd > 0:
            item["normal_sd_deg"] = float(normal_sd)
        if noise > 0:
            item["point_sd"] = float(noise)
        items.append(item)
    source = f"<simulated {model.name}>"
    truth = {"model": model.name, "contact": points[0].tolist(), "normal": normals[0].tolist(),
             "contacts": points.tolist(), "rotation": R.T.tolist(), "translation": (-rotate(R.T, t)).tolist(),
             "noise": {"point": noise, "normal_deg": normal_sd}}
    return TactileData.from_contacts(parse_contacts(items, source), units=units or model.units,
                                     meta={"truth": truth}, source=source)
