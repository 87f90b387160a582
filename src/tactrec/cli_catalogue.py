"""``tactrec catalogue``: write the generated catalogue's meshes (:mod:`tactrec.bench.catalogue`)."""

from __future__ import annotations

__all__ = ["add_catalogue_parser", "cmd_catalogue"]


def add_catalogue_parser(sub, *, count):
    p = sub.add_parser("catalogue", help="write a seeded catalogue of generated meshes (families of solids and "
                       "their near-duplicates, 40-250 mm), to build into a database")
    p.add_argument("--out", required=True, metavar="DIR", help="folder; the meshes go into DIR/v<version>-s<seed>/")
    p.add_argument("--count", type=count(1), default=1000, help="how many meshes, four to a family (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--jobs", type=count(1), default=None, help="worker processes (default: up to 2)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(func=cmd_catalogue)
    return p


def cmd_catalogue(args) -> int:
    from .bench.catalogue import generate
    from .bench.common import default_jobs

    paths = generate(args.out, count=args.count, seed=args.seed, jobs=args.jobs or default_jobs(), quiet=args.quiet)
    if not args.quiet:
        print(f"{paths[0].parent}: {len(paths)} meshes (seed {args.seed}) and catalogue.json; "
              f"'tactrec build {paths[0].parent}/*.ply --units mm --out DB' makes their database")
    return 0
