"""The ``tactrec`` command's sessions: ``recognize SESSION`` and ``next SESSION`` (docs/formats.md)."""

from __future__ import annotations

import json
import sys

from .cli_cluster import add_cluster_option
from .errors import InputError
from .service import DEFAULT_RADIUS_MM, default_radius

__all__ = ["recognize_session", "format_result", "format_session", "cmd_next", "add_next_parser", "cmd_serve",
           "add_serve_parser", "DEFAULT_RADIUS_MM"]


def recognize_session(recognizer, touches):
    """A :class:`~tactrec.session.Session` of ``touches`` (:class:`~tactrec.io.session.SessionTouch`, or
    :class:`~tactrec.io.session.SessionMiss` for a line that met nothing), all added in order."""
    from .io.session import SessionMiss

    session = recognizer.session()
    for t in touches:
        if isinstance(t, SessionMiss):
            session.add_miss(t.line, (t.rotation, t.translation))
        else:
            session.add(t.data, (t.rotation, t.translation))
    return session


def format_result(name: str, result) -> str:
    """The text form of a touch's result (``tactrec recognize`` without ``--json``)."""
    est = result.estimate
    flag = f", confidence {result.confidence:.3f}, unknown {result.unknown:.3f}" if result.best else ""
    flag += ", ambiguous" if result.ambiguous else ""
    if not result.settled:
        flag += ", unsettled: the search's budget ran out before a fit within the noise"
    shape = f"k1 {est.k1:.4g}, k2 {est.k2:.4g}; " if est.reported is not None else ""
    lines = [f"{name}: {'best ' + result.best if result.best else 'no model matches'}"
             f"   ({shape}{result.seconds:.2f} s, method {result.method}{flag})"]
    for rank, r in enumerate(result.ranking, start=1):
        if r.ok:
            loc = ", ".join(f"{x:.4g}" for x in r.location)
            lines.append(f"  {rank:2d}. {r.model:24s} error {r.error:.6g}   candidates {r.candidates:5d}"
                         f"   at ({loc})")
        else:
            lines.append(f"   -. {r.model:24s} rejected: {r.rejected}")
    return "\n".join(lines)


def format_session(name: str, result) -> str:
    """The text form of a session's result."""
    slipped = f", slipped touches {list(result.slipped)}" if result.slipped else ""
    slipped += f", {result.missed} missed line{'s' if result.missed != 1 else ''}" if result.missed else ""
    flag = ", ambiguous" if result.ambiguous else ""
    lines = [f"{name}: {result.touches} touches, best {result.best}   (confidence {result.confidence:.3f}, "
             f"unknown {result.unknown:.3f}{flag}{slipped}; {result.seconds:.2f} s)"]
    p = result.probabilities
    for rank, h in enumerate(result.ranking, start=1):
        per = ", ".join(f"{e:.4g}" for e in h.per_touch)
        lines.append(f"  {rank:2d}. {h.model:24s} error {h.error:.6g}   probability {p.get(h.model, 0.0):.3g}"
                     f"   per touch [{per}]")
    for model, why in result.rejected.items():
        lines.append(f"   -. {model:24s} rejected: {why}")
    return "\n".join(lines)


def cmd_next(args, *, open_models, options, warn) -> int:
    """``tactrec next SESSION --db DB``: where to touch next."""
    from .cli_cluster import opened
    from .io.session import load_session
    from .recognition import Recognizer
    from .runner import workers_for

    touches = load_session(args.session)
    units = next(t.data.units for t in touches if hasattr(t, "data"))
    radius = args.radius if args.radius is not None else default_radius(units)
    db = open_models(db=args.db, models=args.models, warn=warn, quiet=args.quiet, units=args.units, scale=args.scale,
                     fields=args.cluster is None)
    with opened(args) as cluster, Recognizer(db, method=args.method, workers=workers_for(db), cluster=cluster,
                                             unknown_prior=args.unknown_prior, **options) as recognizer:
        session = recognize_session(recognizer, touches)
        if not session.result.ranking:
            raise InputError("no model fits any touch of the session: nothing to propose", args.session)
        proposal = session.next(radius=radius, angle=args.angle, rng=args.seed)
    out = proposal.to_json()
    if args.json:
        sys.stdout.write(json.dumps(out) + "\n")
        return 0
    hyps = ", ".join(f"{h['model']} {h['probability']:.3f}" for h in out["hypotheses"])
    if proposal.contact is None:
        print(f"{args.session}: nothing to propose: {proposal.reason} ({hyps})")
        return 0
    fmt = lambda v: ", ".join(f"{x:.4g}" for x in v)  # noqa: E731
    line = proposal.approach
    print(f"{args.session}: approach from ({fmt(line.start)}) along ({fmt(line.direction)}) for {line.length:.4g}; "
          f"contact expected at ({fmt(proposal.contact)}); expected gain {proposal.gain:.3f} bits")
    for i, d in enumerate([] if proposal.directions is None else proposal.directions, start=1):
        print(f"  curve {i} along ({fmt(d)})")
    print(f"  separates: {hyps}")
    return 0


def add_next_parser(sub, *, positive, mesh_options, methods, default_method) -> None:
    p = sub.add_parser("next", help="propose the touch that best separates a session's hypotheses")
    p.add_argument("session", metavar="SESSION", help="session file (.json; a tactile data file is a session of one)")
    p.add_argument("--db", metavar="DB", help="database built by 'tactrec build'")
    p.add_argument("--models", nargs="+", metavar="MODEL", help="model files or built-in names, instead of --db")
    p.add_argument("--json", action="store_true", help="the proposal as one JSON object")
    p.add_argument("--radius", type=positive, help="how far from an earlier touch's contact the proposed one may be, "
                   f"in the session's units (default {DEFAULT_RADIUS_MM:g} mm)")
    p.add_argument("--angle", type=positive, default=60.0, help="degrees between the proposed curves (default 60)")
    p.add_argument("--method", choices=sorted(methods), default=default_method,
                   help=f"registration method (default {default_method})")
    p.add_argument("--seed", type=int, default=0, help="random seed of the candidate places (default 0)")
    mesh_options(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_cluster_option(p)


def cmd_serve(args, *, open_models, options, warn) -> int:
    """``tactrec serve --db DB``: requests on standard input, answers on standard output (:mod:`tactrec.service`)."""
    from .cli_cluster import opened
    from .recognition import Recognizer
    from .runner import workers_for
    from .service import serve

    db = open_models(db=args.db, models=args.models, warn=warn, quiet=True, units=args.units, scale=args.scale,
                     fields=args.cluster is None)
    with opened(args) as cluster, Recognizer(db, method=args.method, workers=workers_for(db), cluster=cluster,
                                             unknown_prior=args.unknown_prior, **options) as recognizer:
        if not args.quiet:
            print(f"tactrec serve: {len(db)} models, {args.method}; one JSON request per line", file=sys.stderr,
                  flush=True)
        served = serve(recognizer, sys.stdin.buffer, sys.stdout, seed=args.seed)
    if not args.quiet:
        print(f"tactrec serve: {served} requests answered", file=sys.stderr)
    return 0


def add_serve_parser(sub, *, count, mesh_options, methods, default_method):
    p = sub.add_parser("serve", help="keep a database loaded and answer JSON requests, one per line, on "
                       "standard input and output (docs/formats.md)")
    p.add_argument("--db", metavar="DB", help="database built by 'tactrec build'")
    p.add_argument("--models", nargs="+", metavar="MODEL", help="model files or built-in names, instead of --db")
    p.add_argument("--method", choices=sorted(methods), default=default_method,
                   help=f"registration method (default {default_method})")
    # the options of a command that recognises (alike in shape to show's by design, each its own help)
    p.add_argument("--seed", type=count(0), default=0, help="next's seed where a request gives none (default 0)")
    mesh_options(p)
    p.add_argument("--quiet", action="store_true", help="nothing on standard error but errors")
    add_cluster_option(p)
    return p
