"""The ``tactrec`` command: parse, call the library, print.

Bad arguments and bad input exit with status 2 and one line on stderr
naming the file (or argument) and the problem.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from . import __version__
from .errors import InputError, ShardsUnavailable

EXIT_BAD_INPUT = 2


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line."""

    def error(self, message):  # noqa: D401
        raise InputError(message, self.prog)


def _floats(text: str, count: int, what: str):
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise InputError(f"expected {count} comma-separated numbers, got {text!r}", what) from None
    if len(values) != count or not all(np.isfinite(values)):
        raise InputError(f"expected {count} comma-separated finite numbers, got {text!r}", what)
    return np.array(values)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not np.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def _positives(text: str) -> list[float]:
    """Comma-separated positive numbers (an argparse type)."""
    return [_positive(x) for x in text.split(",")]


def _number_option(text: str) -> tuple[str, int | float]:
    """``NAME=NUMBER`` (an argparse type): a whole number stays an int."""
    name, sep, value = text.partition("=")
    if not sep or not name.isidentifier():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    try:
        return name, int(value)
    except ValueError:
        pass
    try:
        return name, float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {value!r}") from None


def _nonnegative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not np.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative number, got {text!r}")
    return value


def _prior(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"a probability in [0, 1) expected, not {text!r}")
    return value


def unknown_prior_option(p) -> None:
    """``--unknown-prior P``: the prior probability that the object is none of the models."""
    from .probability import UNKNOWN_PRIOR

    p.add_argument("--unknown-prior", type=_prior, default=UNKNOWN_PRIOR, metavar="P",
                   help="prior probability that the object is none of the database's models "
                   f"(default {UNKNOWN_PRIOR:g}; 0: every touch is of some model)")


def _count(minimum: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value

    return parse


def _one_source(args, command: str) -> None:
    """Refuse a command given both or neither of ``--db`` and ``--models``."""
    if (args.db is None) == (not args.models):
        raise InputError("give either --db DB or --models MODEL...", f"tactrec {command}")
    if getattr(args, "cluster", None) and args.models:
        raise InputError("--cluster runs on a database's files, which its workers load: build one with "
                         "'tactrec build' and give --db", f"tactrec {command}")


def _warn(line: str) -> None:
    print(f"tactrec: warning: {line}", file=sys.stderr)


# ---------------------------------------------------------------------- commands
def cmd_build(args) -> int:
    from .cli_cluster import opened
    from .database import build_database

    with opened(args) as cluster:
        report = build_database(args.models, args.out, quiet=args.quiet, units=args.units, scale=args.scale,
                                tips=args.tip_radius or (), cluster=cluster)
    if not args.quiet:
        removed = f", {len(report.removed)} old file(s) removed" if report.removed else ""
        print(f"{report.path}: {len(report.built)} built, {len(report.reused)} unchanged{removed}")
        for name in report.built:
            print(f"  built    {name}")
        for name in report.reused:
            print(f"  reused   {name}")
    return 0


def _recognition_options(args) -> dict:
    options = {}
    if args.delta is not None:
        options["delta"] = args.delta
    if args.budget is not None:
        options["budget"] = args.budget
    return options


def cmd_recognize(args) -> int:
    from .database import open_models
    from .engine import preload
    from .io.touch import load_touch
    from .methods import get_method
    from .recognition import Recognizer
    from .runner import workers_for

    _one_source(args, "recognize")
    from .cli_cluster import opened
    from .cli_session import format_result, format_session, recognize_session
    from .io.session import is_session_file, load_session

    method = get_method(args.method)
    method.configure(**_recognition_options(args))                    # a bad option before any work
    loading = preload() if method.uses_engine else None               # the engine, while the data load
    try:
        # validate everything first; a session file is recognised as one object, one pose
        inputs = [load_session(path) if is_session_file(path) else load_touch(path) for path in args.data]
        db = open_models(db=args.db, models=args.models, warn=_warn, quiet=args.quiet, units=args.units,
                         scale=args.scale, fields=args.cluster is None)
    finally:
        if loading is not None:
            loading.join()
    with opened(args) as cluster, \
            Recognizer(db, method=args.method, workers=workers_for(db), unknown_prior=args.unknown_prior,
                       cluster=cluster, **_recognition_options(args)) as recognizer:
        results = [recognize_session(recognizer, x).result if isinstance(x, list) else recognizer.recognize(x)
                   for x in inputs]
    out_lines = []
    for path, x, result in zip(args.data, inputs, results):
        if args.json:
            out_lines.append(json.dumps(dict({"file": str(path)}, **result.to_json())))
        elif isinstance(x, list):
            out_lines.append(format_session(str(path), result))
        else:
            out_lines.append(format_result(str(path), result))
    sys.stdout.write("\n".join(out_lines) + "\n")
    return 0


def cmd_simulate(args) -> int:
    from .cli_simulate import cmd_simulate as run

    return run(args, floats=_floats)


def cmd_show(args) -> int:
    from .cli_show import cmd_show as run
    from .database import open_models

    _one_source(args, "show")
    return run(args, open_models=open_models, warn=_warn)


def cmd_bench(args) -> int:
    from .cli_bench import cmd_bench as run

    return run(args)


def cmd_next(args) -> int:
    from .cli_session import cmd_next as run
    from .database import open_models

    _one_source(args, "next")
    return run(args, open_models=open_models, options={}, warn=_warn)


def cmd_serve(args) -> int:
    from .cli_session import cmd_serve as run
    from .database import open_models
    from .methods import get_method

    _one_source(args, "serve")
    get_method(args.method).configure(**_recognition_options(args))          # a bad option before any work
    return run(args, open_models=open_models, options=_recognition_options(args), warn=_warn)


def cmd_demo(args) -> int:
    from .demo import run_demo

    result = run_demo(seed=args.seed, out=args.out, quiet=args.quiet)
    print(result["text"])
    return 0


# ---------------------------------------------------------------------- parser
def _mesh_options(p) -> None:
    from .units import UNITS

    p.add_argument("--units", choices=sorted(UNITS), help="units of the mesh files' coordinates")
    p.add_argument("--scale", type=_positive, help="factor on the mesh files' coordinates (e.g. 1000 for m to mm)")


def build_parser() -> argparse.ArgumentParser:
    from .cli_cluster import add_cluster_option
    from .methods import DEFAULT_METHOD, METHODS

    parser = _Parser(prog="tactrec", description="Recognise an object and locate a touch on it from three "
                     "(or more) concurrent tactile curves (Ibrayev & Jia).")
    parser.add_argument("--version", action="version", version=f"tactrec {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("demo", help="simulate a touch on a random built-in model and recognise it")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--out", default="tactrec-demo.png",
                   help="picture to write (default tactrec-demo.png); the 3-D page goes beside it, as .html")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("build", help="build a model database from model files or built-in names")
    p.add_argument("models", nargs="+", metavar="MODEL",
                   help="model files (.toml, .ply, .obj, .stl, .off), built-in names, or a built-in set "
                   "(closed-form, paper-table1, ...)")
    p.add_argument("--out", required=True, metavar="DB", help="database folder")
    _mesh_options(p)
    p.add_argument("--tip-radius", type=float, nargs="+", metavar="R",
                   help="also store each mesh's field offset by these tip radii (the meshes' units), at the "
                   "mesh's own spacing; any tip up to 10 mm is read from the stored fields without a build")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    add_cluster_option(p)
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("recognize", help="recognise touches against a database")
    p.add_argument("data", nargs="+", metavar="DATA", help="tactile data files (.json or .csv) or session files "
                   "(.json with 'touches': one object, one pose)")
    p.add_argument("--db", metavar="DB", help="database built by 'tactrec build'")
    p.add_argument("--models", nargs="+", metavar="MODEL", help="model files or built-in names, instead of --db")
    p.add_argument("--json", action="store_true", help="one JSON object per data file, one per line")
    p.add_argument("--method", choices=sorted(METHODS), default=DEFAULT_METHOD,
                   help=f"registration method (default {DEFAULT_METHOD})")
    p.add_argument("--delta", type=_positive, help="lookup tolerance on (k1, k2), 1/model units (method paper)")
    p.add_argument("--budget", type=_count(1), help="the search's budget in closest-point queries per model and "
                   "normal tried (method fast; default 300000, about 0.25 s here on two cores): more buys certainty "
                   "with time")
    _mesh_options(p)
    unknown_prior_option(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_cluster_option(p)
    p.set_defaults(func=cmd_recognize)

    from .cli_session import add_next_parser

    add_next_parser(sub, positive=_positive, mesh_options=_mesh_options, methods=METHODS,
                    default_method=DEFAULT_METHOD)
    unknown_prior_option(sub.choices["next"])
    sub.choices["next"].set_defaults(func=cmd_next)

    from .cli_session import add_serve_parser

    p = add_serve_parser(sub, count=_count, mesh_options=_mesh_options, methods=METHODS, default_method=DEFAULT_METHOD)
    p.add_argument("--delta", type=_positive, help="lookup tolerance on (k1, k2), 1/model units (method paper)")
    p.add_argument("--budget", type=_count(1), help="the search's budget per model and normal tried (method fast)")
    unknown_prior_option(p)
    p.set_defaults(func=cmd_serve)

    from .cli_calibrate import add_calibrate_parser

    add_calibrate_parser(sub, count=_count, methods=METHODS, default_method=DEFAULT_METHOD)

    from .cli_catalogue import add_catalogue_parser

    add_catalogue_parser(sub, count=_count)
    from .cli_simulate import add_simulate_parser

    add_simulate_parser(sub, count=_count, positive=_positive, nonnegative=_nonnegative,
                        mesh_options=_mesh_options).set_defaults(func=cmd_simulate)

    from .cli_show import add_show_parser

    add_show_parser(sub, count=_count, mesh_options=_mesh_options, methods=METHODS,
                    default_method=DEFAULT_METHOD).set_defaults(func=cmd_show)

    from .cli_bench import add_bench_parser

    add_bench_parser(sub, count=_count, positives=_positives, number_option=_number_option,
                     methods=METHODS).set_defaults(func=cmd_bench)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        args.argv = list(sys.argv[1:] if argv is None else argv)          # as typed: a benchmark records it
        return args.func(args)
    except InputError as exc:
        print(f"tactrec: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except ShardsUnavailable as exc:                       # --cluster: a result would leave models out
        from .cli_cluster import EXIT_UNAVAILABLE

        print(f"tactrec: {exc}", file=sys.stderr)
        return EXIT_UNAVAILABLE
    except KeyboardInterrupt:
        print("tactrec: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return 0


if __name__ == "__main__":
    sys.exit(main())
