"""Several touches of one object: random next touches against ``next``'s (``tactrec bench multi-touch``).

Each session places one scan in a random world pose (seeded) and touches it
up to :data:`TOUCHES` times; every touch is simulated on the true object in
a random sensor frame and added with its ``sensor2world`` pose, the models
never seeing the world-to-object pose.  The first touch is the protocol's;
after it two sessions go on from the same first touch:

``random``
    a random place on the true object within ``radius`` of an earlier
    contact (random directions, the protocol's angle);
``next``
    the approach line and directions :meth:`tactrec.session.Session.next`
    proposes: the touch is simulated where the line first meets the true
    object, and a line that meets nothing is added as a missed touch
    (:meth:`tactrec.session.Session.add_miss`).

A ``next`` session stops when nothing is left to separate or confirm (one
hypothesis holds 99% of the probability); its later counts keep its last
answer.  Sets:

``hard-10``
    ``fast-vs-paper``'s hard touches on the ten ``paper-fig11`` scans: contact
    anywhere on a face, 12 mm curves 30 degrees apart, Gaussian noise 0.05 mm,
    no outward side; ``instances`` sessions per scan.
``p3-78``
    P3 touches (contact at a vertex for the first, 24 mm curves 60 degrees
    apart, no noise, outward side known) on all 78 YCB scans against all 78;
    ``ceil(instances / 10)`` sessions per scan.
``similar``
    Objects that share a shape, where one touch rarely tells them apart: each
    of the 78 YCB scans against a database of itself and the
    :data:`SIMILAR` - 1 scans most alike in shape (:func:`similar_scans`: the
    nearest by a scale-free signature of the convex hull: the cracker,
    pudding and gelatin boxes meet each other, a cup its neighbours in size,
    the mug three cups, the master chef can the tomato soup can; the flat
    tuna can meets the bowl), touched as ``hard-10`` is
    (the first touch anywhere on a face); ``ceil(instances / 10)`` sessions
    per scan.
``near-duplicates``
    Each of the ten ``paper-fig11`` scans against itself and a copy with one
    bump (:mod:`tactrec.bench.near_duplicates`), the original touched in even
    instances and the copy in odd ones, the first touch ``hard-10``'s within
    reach of the bump but clear of it: only a touch of the bump tells them
    apart; ``instances`` sessions per scan.
``catalogue``
    ``p3-78``'s sessions against the 1,078 models of ``tactrec bench
    scale-out`` (the 78 scans and 1,000 generated meshes,
    :mod:`tactrec.bench.scale_out`): one session on each of ``instances``
    seeded scans (drawn as that bench draws its scans), the first touch
    searched over the whole catalogue and each later one among the models
    its earlier touches left standing (:mod:`tactrec.session`).  Run only
    when named (:data:`DEFAULT_SETS`); its models are held by one process
    (and its workers): run it with ``--jobs 1``.

The probabilities of ``hard-10`` and ``near-duplicates`` come with their
database's null model of chance fits (:mod:`tactrec.chance`, fitted once on
that database, :func:`tactrec.bench.common.null_model`; a near-duplicates
pair has its own); ``p3-78`` and ``similar`` (a database per scan) are
scored by the fit test alone (:data:`CALIBRATED`).

Reported per set and strategy (:mod:`tactrec.bench.multi_touch_report`),
after 1 to 5 touches: accuracy, mean confidence, ECE, and how often the
session has found the true pose (its pose of the true model fits the touches
kept as well as the true pose does, or as well as their noise allows where
that is looser: :func:`~tactrec.bench.multi_touch_report.truth_found`),
which tells a miss of the
searches from data another model fits as well; the touches a session takes
until its answer is right at confidence >= 0.95 and stays right through its
later touches (or 5), and beside it the touches to reach confidence 0.99 (in
the open world one perfect touch leaves ``unknown`` about 0.012, so 0.99
asks for a second touch whatever is chosen); and the cost of adding a touch against one
touch's recognition, two ways: against the first touches' (same run;
medians), and against the added touch's own recognition, which every add runs
first (the ratio per add; median, p95, max).  The first touches are the
protocol's and often settle early, while later touches land anywhere on a
face, so the first comparison mixes in how hard the touches are.  Where
an add's time goes is reported by stage (:data:`tactrec.session.STAGES`):
how many adds ran each, its share of the adds' seconds, and its seconds over
the touch's own search.
Plots: accuracy against touches, and the reliability of the confidence.
Each strategy's sessions are saved apart, under a hash of the sources that
strategy runs (random places never ask :mod:`tactrec.proposal`), and
``strategies`` runs some of them alone.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..features import Touch
from ..io.atomic import write_text_atomic
from ..io.session import MissedLine
from ..session.fit import per_touch
from ..missed import first_hit
from ..session.result import Hypothesis
from ..simulation import random_rigid_motion, sensor_to_world, simulate_world_touch
from ..surfaces import BUILTIN_SETS
from . import multi_touch_report as report
from .common import (CORE_SOURCES, database, instance_rng, null_model, random_face_site, recognizer, run_parallel,
                     saved_record, simulate, sources_hash, vertex_touch, write_json, ycb_database)

__all__ = ["run", "SETS", "DEFAULT_SETS", "TOUCHES", "STRATEGIES", "SIMILAR", "similar_scans", "shape_signature"]

SETS = ("hard-10", "p3-78", "similar", "near-duplicates", "catalogue")
#: the sets run when none is named: all but ``catalogue`` (1,078 models, about 6 GB and half an hour)
DEFAULT_SETS = SETS[:4]
#: scans in a ``similar`` session's database: the touched one and those most alike in shape
SIMILAR = 4
STRATEGIES = ("random", "next")
TOUCHES = 5
#: world units (mm): how far from an earlier contact a next touch may be
RADIUS = 40.0
SPECS = {"hard-10": {"length": 12.0, "angle": 30.0, "noise": 0.05, "outward": False},
         "similar": {"length": 12.0, "angle": 30.0, "noise": 0.05, "outward": False},
         "near-duplicates": {"length": 12.0, "angle": 30.0, "noise": 0.05, "outward": False},
         "p3-78": {"length": 24.0, "angle": 60.0, "noise": 0.0, "outward": True}}
SPECS["catalogue"] = SPECS["p3-78"]             # the same touches, against the whole catalogue
SPACING = 0.3
#: the sets whose databases have their null model of chance fits (:mod:`tactrec.chance`); the others'
#: probabilities come from the fit test alone (a database per session, or 78 scans to calibrate)
CALIBRATED = ("hard-10", "near-duplicates")
#: a random next touch: places within reach tried (a touch the estimator refuses is no place) and
#: sites drawn in all to find them
ATTEMPTS = 60
DRAWS = 3000


def code_hash(strategy: str) -> str:
    """The sources a strategy's sessions run: random places never ask for a proposal, so a change
    to :mod:`tactrec.proposal` reruns ``next``'s sessions alone."""
    proposal = ("proposal",) if strategy == "next" else ()
    return sources_hash(*CORE_SOURCES, "session", *proposal, "probability.py", "bench/multi_touch.py",
                        "bench/fast_vs_paper.py", "bench/common.py", "bench/scale.py", "bench/near_duplicates.py",
                        "bench/scale_out.py", "bench/catalogue.py")


def shape_signature(model) -> np.ndarray:
    """A scale-free signature of a mesh's shape ``(3,)``: how much of its oriented bounding box its
    convex hull fills (a box 1, a cylinder pi / 4, a ball pi / 6) and the ratios of the box's sorted
    extents, middle to largest and smallest to middle."""
    import trimesh

    hull = trimesh.Trimesh(model.vertices, model.faces, process=False).convex_hull
    box = hull.bounding_box_oriented
    e = np.sort(np.asarray(box.primitive.extents, dtype=np.float64))[::-1]
    return np.array([hull.volume / box.volume, e[1] / e[0], e[2] / e[1]])


def similar_scans(entries, m_index: int, count: int = SIMILAR) -> list[int]:
    """The indices of scan ``m_index`` and the ``count - 1`` scans of ``entries`` nearest to it by
    :func:`shape_signature` (Euclidean; ties by index), in index order."""
    sig = np.array([_signature(e) for e in entries])
    d = np.linalg.norm(sig - sig[m_index], axis=1)
    d[m_index] = -1.0
    return sorted(int(i) for i in np.argsort(d, kind="stable")[:count])


#: a cache: each scan's shape signature, by name
_SIGNATURE_CACHE: dict = {}
#: a cache: each near-duplicates pair, by scan (and the catalogue set's models)
_FAMILY_CACHE: dict = {}


def _signature(entry) -> np.ndarray:
    if entry.name not in _SIGNATURE_CACHE:
        _SIGNATURE_CACHE[entry.name] = shape_signature(entry.model)
    return _SIGNATURE_CACHE[entry.name]


def _first(kind: str, m_index: int, instance: int, seed: int):
    """The set's database (its entries), the touched entry and the protocol's first touch."""
    if kind == "hard-10":
        db = database(tuple(BUILTIN_SETS["paper-fig11"]))
        entry = db.entries[m_index]
        return db.entries, entry, simulate(entry, m_index, instance, seed, "hard")[1]
    if kind == "near-duplicates":
        from . import near_duplicates
        db = database(tuple(BUILTIN_SETS["paper-fig11"]))
        entries, centre = near_duplicates.family(db.entries[m_index], m_index, seed, _FAMILY_CACHE)
        entry, first = near_duplicates.first_touch(entries, centre, m_index, instance, seed, SPECS[kind], SPACING)
        return entries, entry, first
    db = ycb_database()
    entry = db.entries[m_index]
    if kind == "catalogue":
        return _catalogue(), entry, vertex_touch(entry, m_index, instance, seed)[1]
    if kind == "similar":
        chosen = [db.entries[i] for i in similar_scans(db.entries, m_index)]
        return chosen, entry, simulate(entry, m_index, instance, seed, "hard")[1]
    return db.entries, entry, vertex_touch(entry, m_index, instance, seed)[1]


def _catalogue() -> list:
    """The 1,078 models of ``tactrec bench scale-out``: the 78 scans, then the generated meshes (loaded
    once, kept for the rest of this process)."""
    if "catalogue" not in _FAMILY_CACHE:
        from .scale_out import GENERATED, catalogue_entries

        _FAMILY_CACHE["catalogue"] = list(ycb_database().entries) + list(catalogue_entries(GENERATED))
    return _FAMILY_CACHE["catalogue"]


def next_touch(strategy, session, entry, world2model, spec, rng):
    """The next touch's data and ``sensor2world`` pose, the approach line where ``next``'s met nothing on
    the true object, or None (nothing to propose / no place).  A place
    whose simulated touch the estimator rejects (curves tangent at the contact, say) is no place: a
    random one is drawn again, and ``next`` is asked again, as a robot whose touch failed would."""
    points = int(round(spec["length"] / SPACING)) + 1
    R, t, _ = world2model
    contacts = session.contacts()
    drawn = 0
    for _ in range(ATTEMPTS):
        if strategy == "next":
            proposal = session.next(radius=RADIUS, angle=spec["angle"], rng=rng)
            if proposal.contact is None:
                return None
            # the sensor follows the approach line on the true object: it meets it there, or nothing
            truth = Hypothesis("truth", R, t, world2model[2], 0.0, np.zeros(0), ())
            hit = first_hit(entry.model, truth, proposal.approach, SPACING)
            if hit is None:
                return proposal.approach
            if np.array_equal(hit, proposal.approach.start):   # the line starts inside the object: no place
                continue
            contact, directions = hit, proposal.directions
        else:
            # a random place within reach: sites are drawn until one is (on a large object few are)
            while True:
                if drawn >= DRAWS:
                    return None
                drawn += 1
                site = entry.model.random_sites(1, rng=rng)[0] if entry.model.kind != "mesh" else \
                    random_face_site(entry.model, rng)
                frame = entry.model.site_frame(site)
                contact = (frame.point - t) @ R                                         # model -> world
                if np.min(np.linalg.norm(contacts - contact, axis=1)) <= RADIUS:
                    break
            a = rng.uniform(0.0, 2 * np.pi)
            d1, d2 = frame.d1 @ R, frame.d2 @ R
            b = a + np.deg2rad(spec["angle"])
            directions = np.stack([np.cos(a) * d1 + np.sin(a) * d2, np.cos(b) * d1 + np.sin(b) * d2])
        try:
            found = simulate_world_touch(entry.model, world2model, contact, directions, points=points,
                                         spacing=SPACING, noise=spec["noise"], outward=spec["outward"], rng=rng)
            Touch.from_data(found[0], **session.recognizer.estimation)   # data the estimator takes, or not a place
        except ValueError:                              # InputError included
            continue
        return found
    return None


def truth_of(session, entry, world2model) -> dict:
    """What :func:`tactrec.bench.multi_touch_report.truth_found` weighs, over the touches the session
    keeps: the true pose ``world2model``'s points-weighted mean distance (``fit``), the session's pose
    of the true model's (``found``; None without one), the points-weighted mean of the touches'
    :func:`~tactrec.probability.fit_limit` (``limit``, :meth:`~tactrec.session.Session.limit`) and their points."""
    use = session.kept()
    R, t, s = world2model
    truth = per_touch(entry.model, np.asarray(R)[None], np.asarray(t)[None],
                      [session.features[i].points for i in use], s)[0]
    h = session.result.hypothesis(entry.name)
    return {"fit": session.pooled(truth, use),
            "found": None if h is None else session.pooled(np.asarray(h.per_touch)[use], use),
            "limit": session.limit(use),
            "points": int(sum(len(session.features[i].points) for i in use))}


def _session(task) -> dict:
    """One strategy's session: ``task = (set, scan index, instance, seed, strategy)``."""
    kind, m_index, instance, seed, strategy = task
    entries, entry, first = _first(kind, m_index, instance, seed)
    if kind in ("similar", "near-duplicates"):   # a database of its own: its worker processes end with the session
        from ..recognition import Recognizer, default_workers

        with Recognizer(entries, workers=default_workers(), chance=_null(kind, entries)) as own:
            return _run_session(task, own, entry, first)
    return _run_session(task, recognizer(entries, calibrated=kind in CALIBRATED), entry, first)


def _null(kind: str, entries):
    """The null model of chance fits of a set's database (:data:`CALIBRATED`), or None."""
    return null_model(entries) if kind in CALIBRATED else None


def _run_session(task, recognizer_, entry, first) -> dict:
    kind, m_index, instance, seed, strategy = task
    spec = SPECS[kind]
    Rw, tw = random_rigid_motion(instance_rng(seed, m_index, instance, 77), extent=200.0)
    world2model = (Rw.T, -Rw.T @ tw, 1.0)
    rng = instance_rng(seed, m_index, instance, 78 + STRATEGIES.index(strategy))
    session = recognizer_.session()
    steps = []
    touch, pose = first, sensor_to_world(first, (Rw, tw))
    while True:
        start = time.perf_counter()
        if isinstance(touch, MissedLine):            # the approach line met nothing: evidence too
            result = session.add_miss(touch)
        else:
            result = session.add(touch, pose)
        seconds = time.perf_counter() - start
        steps.append({"best": result.best, "correct": result.best == entry.name,
                      "confidence": result.confidence, "unknown": result.unknown, "seconds": seconds,
                      "slipped": list(result.slipped),
                      "evidence": None if result.evidence is None else result.evidence.to_json(),
                      "own_seconds": None if isinstance(touch, MissedLine) else session.records[-1].own.seconds,
                      "missed": isinstance(touch, MissedLine), "stages": dict(result.stages),
                      "truth": truth_of(session, entry, world2model)})
        if len(steps) >= TOUCHES:
            break
        start = time.perf_counter()
        found = next_touch(strategy, session, entry, world2model, spec, rng)
        steps[-1]["propose_seconds"] = time.perf_counter() - start
        if found is None:
            break
        touch, pose = (found, None) if isinstance(found, MissedLine) else found
    return {"set": kind, "model": entry.name, "instance": instance, strategy: steps}


def _saved(job):
    task, folder = job
    return saved_record(folder / f"{task[0]}-{task[1]}-{task[2]}-s{task[3]}.json", lambda: _session(task))


def merged(records: list[dict]) -> list[dict]:
    """One row per session (set, scan, instance) with every strategy's steps, in first-seen order."""
    rows: dict = {}
    for r in records:
        rows.setdefault((r["set"], r["model"], r["instance"]), {}).update(r)
    return list(rows.values())


def run(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False, sets=DEFAULT_SETS,
        strategies=STRATEGIES, **_ignored) -> dict:
    """Run the sessions of ``sets`` with each of ``strategies``; write ``multi-touch.json``, ``.md``
    and the plots.  Each strategy's sessions are saved apart, under a hash of the sources that
    strategy runs (an interrupted or repeated run reuses them)."""
    from ..surfaces import ycb_names

    strategies = tuple(s for s in STRATEGIES if s in strategies)
    if not strategies:
        raise ValueError(f"no strategy to run; known: {', '.join(STRATEGIES)}")
    out = Path(out)
    folders = {s: out / "multi-touch.parts" / f"{s}-{code_hash(s)}" for s in strategies}
    for folder in folders.values():
        folder.mkdir(parents=True, exist_ok=True)
    tasks = []
    for kind in ("hard-10", "near-duplicates"):
        if kind in sets:
            tasks += [(kind, m, i, seed) for m in range(len(BUILTIN_SETS["paper-fig11"])) for i in range(instances)]
    for kind in ("p3-78", "similar"):
        if kind in sets:
            tasks += [(kind, m, i, seed) for m in range(len(ycb_names())) for i in range(math.ceil(instances / 10))]
    if "catalogue" in sets:                          # the scans scale-out draws, one session each
        from .scale_out import scan_picks

        tasks += [("catalogue", m, 0, seed) for m in scan_picks(len(ycb_names()), instances, seed)]
    jobs_ = [(t + (strategy,), folders[strategy]) for t in tasks for strategy in strategies]
    for kind, m in sorted({t[:2] for t in tasks if t[0] in CALIBRATED}):       # fitted once, before the workers
        _null(kind, _first(kind, m, 0, seed)[0])
    records = merged(run_parallel(_saved, jobs_, jobs=jobs or 1, quiet=quiet, desc="multi-touch"))
    by_set = {s: [r for r in records if r["set"] == s] for s in sets}
    table = {"benchmark": "multi-touch", "instances": instances, "seed": seed, "radius_mm": RADIUS,
             "strategies": list(strategies), "touches": TOUCHES,
             "summary": {s: report.summary(rows, strategies, TOUCHES) for s, rows in by_set.items() if rows},
             "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "multi-touch.json", table)
    table["text"] = report.text(table)
    write_text_atomic(out / "multi-touch.md", table["text"])
    report.plot(dict(table, records_by_set=by_set), out)
    return table
