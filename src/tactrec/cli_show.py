"""The ``tactrec show`` command: a touch's or a session's recognition drawn in one offline HTML page, and
its still (:mod:`tactrec.viewer`)."""

from __future__ import annotations

from pathlib import Path

from .errors import InputError

__all__ = ["cmd_show", "add_show_parser", "read_result", "read_proposal"]


def _objects(path) -> list:
    from .io.touch import _read_text, read_json

    source = str(path)
    results = [read_json(line, source) for line in _read_text(Path(path)).splitlines() if line.strip()]
    if not all(isinstance(r, dict) for r in results):
        raise InputError("each line must be a JSON object", source)
    return results


def _direction(obj, what: str, source: str):
    from .io.touch import _vector

    v = _vector(obj, what, source)
    if not float(v @ v) > 0.0:
        raise InputError(f"'{what}' has no length", source)
    return v


def _optional_number(result: dict, key: str, source: str) -> None:
    from .io.touch import number

    if result.get(key) is not None:
        number(result[key], key, source)


def read_result(path, data_path) -> dict:
    """The result for ``data_path`` in a file ``tactrec recognize --json`` wrote (one JSON object a
    line; with several, the line whose ``"file"`` names ``data_path``), validated enough to draw."""
    from .io.session import rigid_pose
    from .io.touch import _vector, number

    source = str(path)
    try:
        results = _objects(path)
    except InputError as e:
        raise InputError(f"not a result of 'tactrec recognize --json': {e.reason}", source) from None
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
        if "scale" in entry and not number(entry["scale"], f"{entry['model']}'s scale", source) > 0:
            raise InputError(f"'{entry['model']}'s scale' must be positive", source)
    if result.get("normal") is not None:
        _direction(result["normal"], "normal", source)
    for key in ("confidence", "unknown"):
        _optional_number(result, key, source)
    slipped = result.get("slipped", [])
    if not isinstance(slipped, list) or not all(isinstance(k, int) and not isinstance(k, bool) for k in slipped):
        raise InputError("'slipped' must be a list of touch numbers", source)
    return result


def read_proposal(path) -> dict:
    """A proposal ``tactrec next --json`` wrote, validated enough to draw."""
    from .io.session import MissedLine
    from .io.touch import _vector

    source = str(path)
    objects = _objects(path)
    if len(objects) != 1:
        raise InputError(f"not one proposal of 'tactrec next --json' ({len(objects)} objects)", source)
    proposal = objects[0]
    if proposal.get("contact") is None:
        return proposal
    _vector(proposal["contact"], "contact", source)
    directions = proposal.get("directions")
    if not isinstance(directions, list) or not directions:
        raise InputError("the proposal has no 'directions'", source)
    for d in directions:
        _direction(d, "direction", source)
    _optional_number(proposal, "gain", source)
    if proposal.get("approach") is not None:
        MissedLine.parse(proposal["approach"], source)
    return proposal


def _session(args, touches, db, result, proposal):
    """The session's result and proposal: as read from ``--result`` and ``--next``, else computed (a
    saved result without ``--next`` is drawn without a proposal)."""
    from .cli_session import recognize_session
    from .recognition import Recognizer
    from .runner import workers_for
    from .service import default_radius

    if result is not None:
        return result, proposal
    with Recognizer(db, method=args.method, workers=workers_for(db)) as recognizer:
        session = recognize_session(recognizer, touches)
        result = session.result.to_json()
        if proposal is None and session.result.ranking:
            units = next(t.data.units for t in touches if hasattr(t, "data"))
            proposal = session.next(radius=default_radius(units), rng=args.seed).to_json()
    return result, proposal


def cmd_show(args, *, open_models, warn) -> int:
    """``tactrec show DATA --db DB --out view.html [--png still.png]``: recognise ``DATA`` (or read
    ``--result``) and write the page and its still."""
    from .io.session import is_session_file, load_session
    from .io.touch import load_touch
    from .recognition import Recognizer
    from .runner import workers_for
    from .viewer import page, render_still, session_scene, touch_scene, write_view
    from .viewer.still import check_still

    if args.out is None and args.png is None:
        raise InputError("give --out HTML, --png PNG or both", "tactrec show")
    if args.png is not None:
        check_still()                                    # before any work: one line if no browser can draw it
    is_session = is_session_file(args.data)
    if args.next and not is_session:
        raise InputError("--next draws a session's proposed touch: DATA is one touch", args.next)
    touches = load_session(args.data) if is_session else [load_touch(args.data)]
    result = read_result(args.result, args.data) if args.result else None
    proposal = read_proposal(args.next) if args.next else None
    db = open_models(db=args.db, models=args.models, warn=warn, quiet=args.quiet, units=args.units, scale=args.scale)
    models = {e.name: e.model for e in db.entries}
    if is_session:
        result, proposal = _session(args, touches, db, result, proposal)
    elif result is None:
        with Recognizer(db, method=args.method, workers=workers_for(db)) as recognizer:
            result = recognizer.recognize(touches[0]).to_json()
    missing = sorted({r["model"] for r in result["ranking"] if r.get("error") is not None} - set(models))
    if missing:
        raise InputError(f"the result names models the database does not hold: {', '.join(missing)}",
                         args.result or args.data)
    title = Path(args.data).name
    if is_session:
        scene = session_scene(result, touches, models, proposal=proposal, shown=args.shown, title=title)
    else:
        scene = touch_scene(result, touches[0].curves, models, shown=args.shown, title=title)
    if args.png is not None:                             # first: a browser that fails leaves nothing written
        render_still(page(scene), args.png)
    if args.out is not None:
        write_view(args.out, scene)
        print(f"wrote {args.out}")
    if args.png is not None:
        print(f"wrote {args.png}")
    return 0


def add_show_parser(sub, *, count, mesh_options, methods, default_method):
    p = sub.add_parser("show", help="draw a touch's or a session's recognition in one offline HTML page, "
                       "or its still")
    p.add_argument("data", metavar="DATA", help="tactile data file (.json or .csv) or session file")
    p.add_argument("--db", metavar="DB", help="database built by 'tactrec build'")
    p.add_argument("--models", nargs="+", metavar="MODEL", help="model files or built-in names, instead of --db")
    p.add_argument("--out", metavar="HTML", help="the page to write")
    p.add_argument("--png", metavar="PNG", help="a still of the page's first view (headless Chromium draws it)")
    p.add_argument("--result", metavar="RESULT", help="a result of 'tactrec recognize --json' for DATA, "
                   "drawn instead of recognising DATA again")
    p.add_argument("--next", metavar="PROPOSAL", help="a session's proposal of 'tactrec next --json', drawn "
                   "instead of proposing again (with --result and no --next, no proposal is drawn)")
    p.add_argument("--shown", type=count(1), default=5, metavar="N",
                   help="how many registered models, best first, the side panel offers (default 5)")
    # the options of a command that recognises (alike in shape to serve's by design, each its own help)
    p.add_argument("--method", choices=sorted(methods), default=default_method,
                   help=f"registration method (default {default_method})")
    p.add_argument("--seed", type=count(0), default=0, help="the proposal's seed, for a session (default 0)")
    mesh_options(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p
