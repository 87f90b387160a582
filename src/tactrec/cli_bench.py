"""The ``tactrec bench`` command: which options each benchmark takes, then the run."""

from __future__ import annotations

from pathlib import Path

from .errors import InputError

__all__ = ["add_bench_parser", "cmd_bench", "PAPER_OPTION_BENCHMARKS", "SCAN_KINDS", "CLUSTER_BENCHMARKS"]


#: benchmarks that take the ``paper`` method's readings (``--paper-option``)
PAPER_OPTION_BENCHMARKS = ("paper-example", "paper-table2", "paper-table3", "paper-table6", "paper-fig11")


def _known(values: list, known, what: str, option: str, name: str) -> tuple:
    """``values`` (an option's comma-separated list) as a tuple, each one of ``known`` (an empty
    item, as from ``--sets ''``, is not)."""
    unknown = [x for x in values if x not in known]
    if unknown:
        raise InputError(f"unknown {what} {unknown[0]!r}; {name} has {', '.join(known)}", option)
    return tuple(values)


#: benchmarks that run on clusters too (``--cluster ADDRESS,...``: each a configuration beside one process)
CLUSTER_BENCHMARKS = ("scale-out",)

#: the benchmarks that take ``--scans``, and which kinds each takes
SCAN_KINDS = {**{name: ("shipped", "paper-like") for name in ("paper-fig11", "paper-table6", "paper-steps")},
              **{name: ("shipped", "other", "cad") for name in ("fast-vs-paper", "fit-limit", "field")}}


def _answers_file(path: str) -> dict:
    """Another run's ``answers.json`` (:mod:`tactrec.bench.answers`), read; one that is not is an
    :class:`InputError` naming it."""
    import json

    try:
        table = json.loads(Path(path).read_text(encoding="utf-8"))
        if not (isinstance(table, dict) and isinstance(table.get("answers"), dict)
                and isinstance(table.get("digests"), dict)):
            raise ValueError("no answers")
    except (OSError, ValueError) as exc:
        raise InputError(f"not an answers.json of tactrec bench answers ({exc.__class__.__name__})", path) from None
    return table


def add_bench_parser(sub, *, count, positives, number_option, methods):
    """The ``bench`` subcommand's parser (its options' checks are :func:`cmd_bench`'s)."""
    import argparse

    from .bench import BENCHMARKS
    from .cli_cluster import add_cluster_option

    width = max(map(len, BENCHMARKS))
    p = sub.add_parser("bench", help="run a reproduction or benchmark (paper-table2, paper-table3, ...)",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog="benchmarks:\n" + "\n".join(f"  {name:<{width}}  {b.summary}"
                                                            for name, b in BENCHMARKS.items())
                       + f"\n\n  {'report':<{width}}  one offline HTML page of every benchmark's latest table and "
                         "plots in --out")
    p.add_argument("name", metavar="NAME", help="benchmark name (listed below)")
    p.add_argument("--instances", type=count(1), default=10, help="instances per model (default 10)")
    p.add_argument("--first-instance", type=count(0), default=None, metavar="K",
                   help="contacts: run instances K to --instances less one (a run split over machines; default 0)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--jobs", type=count(1), default=None, help="worker processes (default: up to 2)")
    p.add_argument("--method", choices=sorted(methods), default="paper",
                   help="method of the paper-* reproductions (default paper)")
    p.add_argument("--scans", choices=("shipped", "paper-like", "other", "cad"), default=None,
                   help="paper-fig11, paper-table6, paper-steps: the YCB scans as shipped (paper-steps: paper-like), "
                        "or scaled to 60-95 mm and Loop-subdivided to the paper's resolution; fast-vs-paper, "
                        "fit-limit, field: 'other' for 14 free-form meshes from other sources (fetched once), 'cad' "
                        "for 10 machined parts with sharp edges and flat faces (made by code)")
    p.add_argument("--delta-only", action="store_true",
                   help="paper-fig11: only the delta sweep (one recognition per touch), l and phi at the defaults")
    p.add_argument("--lengths", type=positives, default=None, metavar="MM,...",
                   help="paper-fig11: the curve lengths l of the l sweep (default 9,12,15,18,21,24)")
    p.add_argument("--angles", type=positives, default=None, metavar="DEG,...",
                   help="paper-fig11: the plane separations phi of the phi sweep (default 10,20,30,40,50,60)")
    p.add_argument("--paper-option", type=number_option, action="append", metavar="NAME=VALUE",
                   help="paper-example, paper-table2/3/6, paper-fig11: an option of the paper method, one of its "
                        "readings of the paper (e.g. parabola_points=3, phi_step=5); repeatable")
    p.add_argument("--sets", type=lambda text: text.split(","), metavar="SET,...",
                   help="calibration (hard, p3-78), multi-touch (hard-10, p3-78, similar, near-duplicates; "
                        "catalogue, 1,078 models, only when named), open-world, sensor and patch "
                        "(fig11, other; open-world also cad; patch also ycb, the 78, only when named): "
                        "which sets to run")
    p.add_argument("--radii", type=positives, metavar="MM,...", help="patch: the patches' radii (default 2,4,6,10)")
    p.add_argument("--blur", type=float, metavar="MM", help="patch: the gel's blur sigma (default 0)")
    p.add_argument("--stated-noise", action="store_true", help="patch: each map states its depth noise")
    p.add_argument("--strategies", type=lambda text: text.split(","), metavar="NAME,...",
                   help="where each touch goes (random, next): multi-touch both by default, contacts random")
    p.add_argument("--settings", type=lambda text: text.split(","), metavar="NAME,...",
                   help="sensor: which settings to run besides clean ('tip 1 mm', 'outliers 3%%', ...; default all)")
    p.add_argument("--against", metavar="FILE", default=None,
                   help="answers: another run's answers.json, to list the entries whose JSON differs")
    p.add_argument("--out", metavar="DIR", help="output folder (default bench-out)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_cluster_option(p, several=True)
    return p


def cmd_bench(args) -> int:
    import shlex

    from .bench import BENCHMARKS
    from .bench.report import record_run, write_report

    if args.name == "report":
        written = write_report(Path(args.out) if args.out else Path("bench-out"))
        print(f"wrote {written}")
        return 0
    if args.name not in BENCHMARKS:
        raise InputError(f"unknown benchmark; available: {', '.join(sorted(BENCHMARKS))} (and report)", args.name)
    out = Path(args.out) if args.out else Path("bench-out")
    extra = {}
    if args.scans is not None:
        kinds = SCAN_KINDS.get(args.name)
        if kinds is None:
            raise InputError(f"--scans applies to {', '.join(SCAN_KINDS)} only", args.name)
        if args.scans not in kinds:
            listed = " or ".join([", ".join(kinds[:-1]), kinds[-1]] if len(kinds) > 1 else list(kinds))
            raise InputError(f"{args.name} takes --scans {listed}, not {args.scans}", args.name)
    for option, value in (("--delta-only", args.delta_only or None), ("--lengths", args.lengths),
                          ("--angles", args.angles)):
        if value is not None and args.name != "paper-fig11":
            raise InputError(f"{option} applies to paper-fig11 only", args.name)
    if args.paper_option and args.name not in PAPER_OPTION_BENCHMARKS:
        raise InputError(f"--paper-option applies to {', '.join(PAPER_OPTION_BENCHMARKS)} only", args.name)
    if args.delta_only and (args.lengths or args.angles):
        raise InputError("--delta-only leaves l and phi at the defaults; give it or --lengths/--angles", args.name)
    if args.scans is not None:
        extra["scans"] = args.scans
    if args.sets is not None:
        from .bench.calibration import SETS as CALIBRATION_SETS
        from .bench.contacts import SETS as CONTACT_SETS
        from .bench.multi_touch import SETS as SESSION_SETS
        from .bench.open_world import EXTRA_SETS, SCAN_SETS
        from .bench.patch import SETS as PATCH_SETS
        from .bench.sensor import SCAN_SETS as SENSOR_SETS

        known = {"calibration": CALIBRATION_SETS, "multi-touch": SESSION_SETS, "open-world": SCAN_SETS + EXTRA_SETS,
                 "sensor": SENSOR_SETS, "patch": PATCH_SETS, "contacts": CONTACT_SETS,
                 "contact-search": CONTACT_SETS}.get(args.name)
        if known is None:
            raise InputError("--sets applies to calibration, multi-touch, open-world, sensor, patch, contacts and "
                             "contact-search only", args.name)
        extra["sets"] = _known(args.sets, known, "set", "--sets", args.name)
    if args.strategies is not None:
        from .bench.contacts import STRATEGIES as CONTACT_STRATEGIES
        from .bench.multi_touch import STRATEGIES

        known = {"multi-touch": STRATEGIES, "contacts": CONTACT_STRATEGIES}.get(args.name)
        if known is None:
            raise InputError("--strategies applies to multi-touch and contacts only", args.name)
        extra["strategies"] = _known(args.strategies, known, "strategy", "--strategies", args.name)
    if args.settings is not None:
        from .bench.sensor import SETTINGS

        if args.name != "sensor":
            raise InputError("--settings applies to sensor only", args.name)
        extra["settings"] = ("clean",) + tuple(s for s in _known(args.settings, SETTINGS, "setting", "--settings",
                                                                 args.name) if s != "clean")
    for option, value in (("--radii", args.radii), ("--blur", args.blur),
                          ("--stated-noise", args.stated_noise or None)):
        if value is not None and args.name != "patch":
            raise InputError(f"{option} applies to patch only", args.name)
    if args.stated_noise:
        extra["stated"] = True
    if args.first_instance is not None:
        if args.name != "contacts":
            raise InputError("--first-instance applies to contacts only", args.name)
        if args.first_instance >= args.instances:
            raise InputError(f"--first-instance {args.first_instance} leaves no instance below --instances "
                             f"{args.instances}", args.name)
        extra["first"] = args.first_instance
    if args.radii is not None:
        extra["radii"] = tuple(args.radii)
    if args.blur is not None:
        if not args.blur >= 0:
            raise InputError(f"--blur must be a non-negative number of mm (got {args.blur:g})", args.name)
        extra["blur"] = float(args.blur)
    if args.against is not None:
        if args.name != "answers":
            raise InputError("--against applies to answers only", args.name)
        extra["against"] = _answers_file(args.against)
    if args.paper_option:
        extra["options"] = dict(args.paper_option)
    if args.cluster is not None:
        if args.name not in CLUSTER_BENCHMARKS:
            raise InputError(f"--cluster applies to {', '.join(CLUSTER_BENCHMARKS)} only", args.name)
        extra["cluster"] = args.cluster
    if args.delta_only or args.lengths or args.angles:
        from .bench.paper_fig11 import DEFAULTS, SWEEPS

        defaults = args.delta_only
        extra["sweeps"] = {"delta": SWEEPS["delta"],
                           "length": [DEFAULTS["length"]] if defaults else args.lengths or SWEEPS["length"],
                           "angle": [DEFAULTS["angle"]] if defaults else args.angles or SWEEPS["angle"]}
    table = BENCHMARKS[args.name].run(out=out, instances=args.instances, seed=args.seed, jobs=args.jobs,
                                  quiet=args.quiet, method=args.method, **extra)
    print(table["text"])
    written = out / (table.get("benchmark", args.name) + ".json")
    record_run(written, command=shlex.join(["tactrec", *getattr(args, "argv", ["bench", args.name])]),
               text=table["text"], plots=table.get("plots", []))
    print(f"wrote {written}" + "".join(f", {p}" for p in table.get("plots", [])))
    return 0
