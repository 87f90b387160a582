"""The ``tactrec simulate`` command: a touch simulated on a model, as a real sensor records it (docs/formats.md)."""

from __future__ import annotations

import numpy as np

from .errors import InputError

__all__ = ["cmd_simulate", "add_simulate_parser"]


def cmd_simulate(args, *, floats) -> int:
    """``tactrec simulate MODEL --out DATA``: a simulated touch, as a real sensor records it with the sensor options."""
    from .io.touch import save_touch
    from .sensor import Imperfections
    from .simulation import simulate_contacts, simulate_patch, simulate_random_touch, simulate_touch
    from .surfaces import load_model

    model = load_model(args.model, units=args.units, scale=args.scale)
    given = [x for x in (args.at, args.uv, args.vertex) if x is not None]
    if len(given) > 1:
        raise InputError("give at most one of --at, --uv, --vertex", "tactrec simulate")
    if args.vertex is not None and model.kind != "mesh":
        raise InputError("--vertex is for mesh models; use --uv or --at on a closed-form surface", args.model)
    if args.uv is not None and model.kind != "closed-form":
        raise InputError("--uv is for closed-form surfaces; use --vertex or --at on a mesh", args.model)
    rng = np.random.default_rng(args.seed)
    spacing = args.spacing if args.spacing is not None else model.size / 100.0
    try:
        imperfections = Imperfections(tip_radius=args.tip_radius, uneven=args.uneven, jitter=args.jitter,
                                      outliers=args.outliers, miss=args.miss, bend=args.bend)
    except ValueError as exc:
        raise InputError(str(exc), "tactrec simulate") from None
    options = dict(points=args.points, spacing=spacing, angle=args.angle, curves=args.curves, noise=args.noise,
                   noise_kind=args.noise_kind, outward=not args.no_outward, contact=args.contact,
                   sensor_frame=not args.model_frame, imperfections=imperfections)
    patch = dict(radius=args.patch, pitch=args.pitch, noise=args.noise, blur=args.blur, depth=args.depth,
                 sensor_frame=not args.model_frame, stated=args.state_noise)
    if args.patch is None and (any(x is not None for x in (args.pitch, args.blur, args.depth)) or args.state_noise):
        raise InputError("--pitch, --blur, --depth and --state-noise are for a patch: give --patch RADIUS",
                         "tactrec simulate")
    if args.contacts is not None and (args.patch is not None or given):
        raise InputError("--contacts spreads its contacts over the object: give no --patch, --at, --uv or --vertex",
                         "tactrec simulate")
    if args.contacts is None and args.normal_sd is not None:
        raise InputError("--normal-sd is for contacts: give --contacts N", "tactrec simulate")
    try:
        if args.at is not None:
            site = model.locate(floats(args.at, 3, "--at"))
        elif args.uv is not None:
            site = model.wrap(floats(args.uv, 2, "--uv"))
        elif args.vertex is not None:
            site = np.array([args.vertex])
        else:
            site = None
        if args.contacts is not None:
            data = simulate_contacts(model, args.contacts, noise=args.noise, normal_sd=args.normal_sd or 0.0,
                                     sensor_frame=not args.model_frame, rng=rng)
        elif args.patch is not None:
            patch = {k: v for k, v in patch.items() if v is not None}
            data = (simulate_patch(model, site, rng=rng, **patch) if site is not None
                    else simulate_random_touch(model, rng=rng, maker=simulate_patch, **patch))
        else:
            data = (simulate_touch(model, site, rng=rng, **options) if site is not None
                    else simulate_random_touch(model, rng=rng, **options))
    except InputError:
        raise  # already names its argument (--at, --uv)
    except ValueError as exc:
        raise InputError(str(exc), args.model) from None
    save_touch(data, args.out)
    if not args.quiet:
        t = data.meta["truth"]
        if data.contacts is not None:
            print(f"{args.out}: {len(data.contacts)} contacts on {model.name}")
            return 0
        if data.patch is not None:
            print(f"{args.out}: a patch of {len(data.patch.points)} points, radius {args.patch:g}, pitch "
                  f"{data.patch.pitch:.4g}, on {model.name} at ({', '.join(f'{x:.4g}' for x in t['contact'])})")
            return 0
        counts = sorted({len(c) for c in data.curves})
        print(f"{args.out}: {len(data.curves)} curves x {'-'.join(str(n) for n in counts[::max(len(counts) - 1, 1)])} "
              f"points on {model.name} at "
              f"({', '.join(f'{x:.4g}' for x in t['contact'])}), spacing {spacing:.4g}")
    return 0


def add_simulate_parser(sub, *, count, positive, nonnegative, mesh_options):
    p = sub.add_parser("simulate", help="generate tactile data on a model")
    p.add_argument("model", metavar="MODEL", help="model file or built-in name")
    p.add_argument("--out", required=True, metavar="DATA", help="data file to write (.json or .csv)")
    p.add_argument("--at", metavar="X,Y,Z", help="contact near this point (model frame); write --at=-1,2,3 "
                   "when the first number is negative")
    p.add_argument("--uv", metavar="U,V", help="contact at these parameters (closed-form surface)")
    p.add_argument("--vertex", type=count(0), metavar="I", help="contact at this vertex (mesh)")
    p.add_argument("--points", type=count(5), default=61, help="points per curve (default 61)")
    p.add_argument("--spacing", type=positive, help="arc length between points (default: model size / 100)")
    p.add_argument("--angle", type=positive, default=60.0, help="degrees between adjacent planes (default 60)")
    p.add_argument("--curves", type=count(3), default=3, help="number of curves (default 3)")
    p.add_argument("--noise", type=nonnegative, default=0.0, help="noise amplitude (uniform) or sigma (gaussian)")
    p.add_argument("--noise-kind", choices=["uniform", "gaussian"], default="uniform")
    p.add_argument("--no-outward", action="store_true", help="leave out the outward hint")
    p.add_argument("--contact", action="store_true", help="include the (noise-free) contact point")
    p.add_argument("--model-frame", action="store_true", help="no random rigid motion (data in the model frame)")
    sensor = p.add_argument_group("as a real sensor records (model units; see tactrec.sensor)")
    sensor.add_argument("--tip-radius", type=nonnegative, default=0.0,
                        help="the points are the centres of a spherical tip of this radius")
    sensor.add_argument("--uneven", type=nonnegative, default=1.0,
                        help="ratio of the longest step between points to the shortest (default 1: even)")
    sensor.add_argument("--jitter", type=nonnegative, default=0.0, help="Gaussian sigma on every coordinate")
    sensor.add_argument("--outliers", type=nonnegative, default=0.0,
                        help="share of the points moved 0.5-3 units off the trace (below 0.5)")
    sensor.add_argument("--miss", type=nonnegative, default=0.0,
                        help="how far each curve passes from the contact")
    sensor.add_argument("--bend", type=nonnegative, default=0.0,
                        help="how far each stroke leaves its plane at its ends")
    gel = p.add_argument_group("a patch, as a vision-based skin records it (model units; --noise: the depth's "
                               "Gaussian sigma)")
    gel.add_argument("--patch", type=positive, metavar="RADIUS", help="a height map over a disc of this radius "
                     "instead of curves")
    gel.add_argument("--pitch", type=positive, help="the pixels' spacing (default: about 400 pixels in the disc)")
    gel.add_argument("--blur", type=nonnegative, help="the gel's smoothing, a Gaussian of this sigma (default 0)")
    gel.add_argument("--depth", type=positive, help="the deepest the sensor sees below its plane (default RADIUS)")
    gel.add_argument("--state-noise", action="store_true", help="the map states its depth noise (point_sd), as a "
                     "calibrated sensor's would")
    single = p.add_argument_group("single contacts, as a probe or a force/torque sensor records them (--noise: "
                                  "each point's Gaussian sigma)")
    single.add_argument("--contacts", type=count(1), metavar="N", help="N contacts spread over the object (uniform "
                        "over its area) instead of curves")
    single.add_argument("--normal-sd", type=nonnegative, metavar="DEG", help="each normal's tilt, a Gaussian of "
                        "this many degrees per direction (default 0)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    mesh_options(p)
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    return p
