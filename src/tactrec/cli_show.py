"""The ``tactrec show`` command: a touch's recognition drawn in one offline HTML page (:mod:`tactrec.viewer`)."""

from __future__ import annotations

from pathlib import Path

from .errors import InputError

__all__ = ["cmd_show", "add_show_parser", "read_result"]


def read_result(path, data_path) -> dict:
    """The result for ``data_path`` in a file ``tactrec recognize --json`` wrote (one JSON object a
    line; with several, the line whose ``"file"`` names ``data_path``), validated enough to draw."""
    from .io.session import rigid_pose
    from .io.touch import _read_text, _vector, read_json

    source = str(path)
    lines = [line for line in _read_text(Path(path)).splitlines() if line.strip()]
    results = [read_json(line, source) for line in lines]
    if not all(isinstance(r, dict) for r in results):
        raise InputError("not a result of 'tactrec recognize --json': each line must be a JSON object", source)
    if len(results) > 1:
        named = [r for r in results if Path(str(r.get("file", ""))).name == Path(data_path).name]
        if len(named) != 1:
            raise InputError(f"{len(results)} results and {len(named)} for {Path(data_path).name}", source)
        results = named
    result = results[0]
    ranking = result.get("ranking")
    if not isinstance(ranking, list) or not ranking:
        raise InputError("the result has no 'ranking'", source)
    for entry in ranking:
        if not isinstance(entry, dict) or "model" not in entry:
            raise InputError("each ranking entry needs a 'model'", source)
        if entry.get("error") is None:
            continue
        rigid_pose(entry.get("rotation"), entry.get("translation"), source, f"{entry['model']}'s pose")
        _vector(entry.get("location"), f"{entry['model']}'s location", source)
    return result


def cmd_show(args, *, open_models, warn) -> int:
    """``tactrec show DATA --db DB --out view.html``: recognise ``DATA`` (or read ``--result``) and
    write the page."""
    from .io.session import is_session_file
    from .io.touch import load_touch
    from .recognition import Recognizer
    from .runner import workers_for
    from .viewer import touch_scene, write_view

    if is_session_file(args.data):
        raise InputError("a session file is not drawn yet: give one of its touches", args.data)
    touch = load_touch(args.data)
    result = read_result(args.result, args.data) if args.result else None
    db = open_models(db=args.db, models=args.models, warn=warn, quiet=args.quiet, units=args.units, scale=args.scale)
    models = {e.name: e.model for e in db.entries}
    if result is None:
        with Recognizer(db, method=args.method, workers=workers_for(db)) as recognizer:
            result = recognizer.recognize(touch).to_json()
    missing = sorted({r["model"] for r in result["ranking"] if r.get("error") is not None} - set(models))
    if missing:
        raise InputError(f"the result names models the database does not hold: {', '.join(missing)}",
                         args.result or args.data)
    scene = touch_scene(result, touch.curves, models, shown=args.shown, title=Path(args.data).name)
    write_view(args.out, scene)
    print(f"wrote {args.out}")
    return 0


def add_show_parser(sub, *, count, mesh_options, methods, default_method):
    p = sub.add_parser("show", help="draw a touch's recognition in one offline HTML page")
    p.add_argument("data", metavar="DATA", help="tactile data file (.json or .csv)")
    p.add_argument("--db", metavar="DB", help="database built by 'tactrec build'")
    p.add_argument("--models", nargs="+", metavar="MODEL", help="model files or built-in names, instead of --db")
    p.add_argument("--out", required=True, metavar="HTML", help="the page to write")
    p.add_argument("--result", metavar="RESULT", help="a result of 'tactrec recognize --json' for DATA, "
                   "drawn instead of recognising DATA again")
    p.add_argument("--shown", type=count(1), default=5, metavar="N",
                   help="how many registered models, best first, the side panel offers (default 5)")
    p.add_argument("--method", choices=sorted(methods), default=default_method,
                   help=f"registration method (default {default_method})")
    mesh_options(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p
