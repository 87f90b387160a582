"""``tactrec calibrate``: fit a database's null model of chance fits (:mod:`tactrec.chance`)."""

from __future__ import annotations

import sys


def _range(text: str) -> tuple[float, float]:
    import argparse

    try:
        lo, hi = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not two numbers MIN,MAX: {text!r}") from None
    if not (0 < lo <= hi < float("inf")):
        raise argparse.ArgumentTypeError(f"need 0 < MIN <= MAX, got {text!r}")
    return lo, hi


def _kinds(text: str) -> tuple[str, ...]:
    import argparse

    from .chance import KINDS

    kinds = tuple(k.strip() for k in text.split(","))
    if not all(k in KINDS for k in kinds):
        raise argparse.ArgumentTypeError(f"kinds among {','.join(KINDS)}, not {text!r}")
    return kinds


def add_calibrate_parser(sub, *, count, methods, default_method):
    p = sub.add_parser("calibrate", help="fit a database's null model of chance fits: how often a touch fits a "
                       "model it did not touch (stored with the database; run again when its models change)")
    p.add_argument("--db", required=True, metavar="DB", help="database built by 'tactrec build'")
    p.add_argument("--touches", type=count(2), default=None,
                   help="seeded touches per model, each recognised with the model and without it (default 16)")
    p.add_argument("--lengths", type=_range, default=None, metavar="MIN,MAX",
                   help="the calibration touches' curve lengths, the models' units (default 8,32): the small noisy "
                   "ones over the lower half, the clean ones over the upper")
    p.add_argument("--noise", type=_range, default=None, metavar="MIN,MAX",
                   help="the small touches' noise sigma, the models' units (default 0.01,0.08)")
    p.add_argument("--kinds", type=_kinds, default=("curves", "patch"), metavar="KIND[,KIND]",
                   help="the kinds of calibration touch, each weighed against its own (curves, patch, contacts; "
                   "default curves,patch: a touch of contacts is searched by triangles of places, tens of "
                   "seconds a touch)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--method", choices=sorted(methods), default=default_method,
                   help=f"the method whose fits are calibrated (default {default_method})")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(func=cmd_calibrate)
    return p


def cmd_calibrate(args) -> int:
    from tqdm import tqdm

    from .chance import save
    from .chance.fit import LENGTHS, NOISE, TOUCHES, calibrate
    from .database import load_database
    from .recognition import Recognizer
    from .runner import default_workers

    db = load_database(args.db, warn=lambda line: None)
    touches = args.touches or TOUCHES
    bar = tqdm(total=touches * len(db) * len(args.kinds), desc="calibrating", unit="touch", file=sys.stderr,
               disable=args.quiet or not sys.stderr.isatty(), leave=False)
    with Recognizer(db.entries, method=args.method, workers=default_workers()) as recognizer:
        model = calibrate(recognizer, touches=touches, seed=args.seed, lengths=args.lengths or LENGTHS,
                          noise=args.noise or NOISE, kinds=args.kinds, progress=lambda name: bar.update())
    bar.close()
    path = save(model, args.db)
    if not args.quiet:
        print(f"{path}: {len(model)} touches ({', '.join(args.kinds)}) of {len(db)} models (seed {args.seed}); "
              f"the regression's prior "
              f"precision {model.penalty:g}, chosen by cross-validation over the models")
    return 0
