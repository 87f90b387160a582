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
    the place and directions :meth:`tactrec.session.Session.next` proposes,
    simulated on the true object there.

A ``next`` session stops when nothing is left to separate (one hypothesis
holds 99% of the probability); its later counts keep its last answer.  Sets:

``hard-10``
    ``fast-vs-paper``'s hard touches on the ten ``paper-fig11`` scans: contact
    anywhere on a face, 12 mm curves 30 degrees apart, Gaussian noise 0.05 mm,
    no outward side; ``instances`` sessions per scan.
``p3-78``
    P3 touches (contact at a vertex for the first, 24 mm curves 60 degrees
    apart, no noise, outward side known) on all 78 YCB scans against all 78;
    ``ceil(instances / 10)`` sessions per scan.

Reported per set and strategy, after 1 to 5 touches: accuracy, mean
confidence, ECE, and how often the session has found the true pose (its pose
of the true model fits the touches kept as well as the true pose does: within
three standard errors of its mean distance), which tells a miss of the
searches from data another model fits as well; the touches a session takes to
reach confidence 0.99 (or 5); and the cost of adding a touch against one
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
from ..session import STAGES
from ..session_fit import per_touch
from ..simulation import random_rigid_motion, sensor_to_world, simulate_world_touch
from ..surfaces import BUILTIN_SETS
from .calibration import expected_calibration_error
from .common import (CORE_SOURCES, instance_rng, random_face_site, recognizer, run_parallel, saved_record,
                     sources_hash, write_json)

__all__ = ["run", "SETS", "TOUCHES", "STRATEGIES"]

SETS = ("hard-10", "p3-78")
STRATEGIES = ("random", "next")
TOUCHES = 5
#: world units (mm): how far from an earlier contact a next touch may be
RADIUS = 40.0
SPECS = {"hard-10": {"length": 12.0, "angle": 30.0, "noise": 0.05, "outward": False},
         "p3-78": {"length": 24.0, "angle": 60.0, "noise": 0.0, "outward": True}}
SPACING = 0.3
#: a random next touch: places within reach tried (a touch the estimator refuses is no place) and
#: sites drawn in all to find them
ATTEMPTS = 60
DRAWS = 3000


def _code_hash(strategy: str) -> str:
    """The sources a strategy's sessions run: random places never ask for a proposal, so a change
    to :mod:`tactrec.proposal` reruns ``next``'s sessions alone."""
    proposal = ("proposal.py",) if strategy == "next" else ()
    return sources_hash(*CORE_SOURCES, "session.py", "session_fit.py", "session_pairs.py", "session_result.py",
                        "session_family.py", *proposal, "probability.py", "bench/multi_touch.py",
                        "bench/fast_vs_paper.py", "bench/scale.py")


def _first(kind: str, m_index: int, instance: int, seed: int):
    """The set's database, the touched entry and the protocol's first touch."""
    if kind == "hard-10":
        from .fast_vs_paper import _database, _simulate

        db = _database(tuple(BUILTIN_SETS["paper-fig11"]))
        entry = db.entries[m_index]
        return db, entry, _simulate(entry, m_index, instance, seed, "hard")[1]
    from . import scale

    db = scale._database()
    entry = db.entries[m_index]
    return db, entry, scale._touch(entry, m_index, instance, seed)[1]


def _next_touch(strategy, session, entry, world2model, spec, rng):
    """The next touch's data and ``sensor2world`` pose, or None (nothing to propose / no place).  A place
    whose simulated touch the estimator rejects (curves tangent at the contact, say) is no place: a
    random one is drawn again, and ``next`` is asked again, as a robot whose touch failed would."""
    points = int(round(spec["length"] / SPACING)) + 1
    R, t, _ = world2model
    contacts = np.array([w.contact if w.contact is not None else f.geometry.contact
                         for w, f in zip(session.world, session.features)])
    drawn = 0
    for _ in range(ATTEMPTS):
        if strategy == "next":
            proposal = session.next(radius=RADIUS, angle=spec["angle"], rng=rng)
            if proposal.contact is None:
                return None
            contact, directions = proposal.contact, proposal.directions
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


def _truth_found(session, entry, world2model) -> bool:
    """Whether the session's pose of the true model fits the touches kept as well as the true pose
    ``world2model`` does (points-weighted mean distance within the session's own allowance,
    :data:`~tactrec.session.CONSISTENT_SE` standard errors, of the truth's)."""
    h = session.result.hypothesis(entry.name)
    if h is None:
        return False
    use = session.kept()
    R, t, s = world2model
    truth = per_touch(entry.model, np.asarray(R)[None], np.asarray(t)[None],
                      [session.features[i].points for i in use], s)[0]
    best = session.pooled(truth, use)
    return bool(session.pooled(np.asarray(h.per_touch)[use], use) <= session.allowed(best, use))


def _session(task) -> dict:
    """One strategy's session: ``task = (set, scan index, instance, seed, strategy)``."""
    kind, m_index, instance, seed, strategy = task
    db, entry, first = _first(kind, m_index, instance, seed)
    spec = SPECS[kind]
    Rw, tw = random_rigid_motion(instance_rng(seed, m_index, instance, 77), extent=200.0)
    world2model = (Rw.T, -Rw.T @ tw, 1.0)
    rng = instance_rng(seed, m_index, instance, 78 + STRATEGIES.index(strategy))
    session = recognizer(db.entries).session()
    steps = []
    touch, pose = first, sensor_to_world(first, (Rw, tw))
    while True:
        start = time.perf_counter()
        result = session.add(touch, pose)
        seconds = time.perf_counter() - start
        steps.append({"best": result.best, "correct": result.best == entry.name,
                      "confidence": result.confidence, "seconds": seconds, "slipped": list(result.slipped),
                      "own_seconds": session.solo[-1].seconds, "stages": dict(result.stages),
                      "truth_found": _truth_found(session, entry, world2model)})
        if len(steps) >= TOUCHES:
            break
        start = time.perf_counter()
        found = _next_touch(strategy, session, entry, world2model, spec, rng)
        steps[-1]["propose_seconds"] = time.perf_counter() - start
        if found is None:
            break
        touch, pose = found
    return {"set": kind, "model": entry.name, "instance": instance, strategy: steps}


def _saved(job):
    task, folder = job
    return saved_record(folder / f"{task[0]}-{task[1]}-{task[2]}-s{task[3]}.json", lambda: _session(task))


def _at(steps: list, k: int) -> dict:
    """The session's state after ``k`` touches (its last, if it stopped before)."""
    return steps[min(k, len(steps)) - 1]


def _quantiles(values) -> dict:
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return {"median": None, "p95": None, "max": None}
    return {"median": float(np.median(v)), "p95": float(np.percentile(v, 95)), "max": float(v.max())}


def _over_own(step: dict) -> float | None:
    """An add's time over the added touch's own recognition (None where that was not timed)."""
    return step["seconds"] / step["own_seconds"] if step.get("own_seconds") else None


def _stages(adds: list[dict]) -> dict:
    """Where the adds' time goes, per stage of :data:`tactrec.session.STAGES`: how many adds ran it,
    its share of all the adds' seconds, and its seconds over the added touch's own search (median
    over the adds that ran it)."""
    adds = [a for a in adds if a.get("stages") and a.get("own_seconds")]
    total = sum(a["seconds"] for a in adds)
    out = {}
    for stage in STAGES:
        ran = [a for a in adds if a["stages"].get(stage, 0.0) > 0.0]
        out[stage] = {"adds": len(ran), "share": sum(a["stages"][stage] for a in ran) / total if total else None,
                      "over_own_median": float(np.median([a["stages"][stage] / a["own_seconds"] for a in ran]))
                      if ran else None}
    return out


def summary(rows: list[dict], strategies=STRATEGIES) -> dict:
    """Per strategy of ``strategies`` (each row has every one), the figures of the module text."""
    out = {}
    first = [r[strategy][0]["seconds"] for r in rows for strategy in strategies]
    for strategy in strategies:
        per_k = []
        for k in range(1, TOUCHES + 1):
            states = [_at(r[strategy], k) for r in rows]
            conf = [s["confidence"] for s in states]
            ok = [s["correct"] for s in states]
            found = [s["truth_found"] for s in states if "truth_found" in s]
            per_k.append({"touches": k, "accuracy_percent": 100.0 * float(np.mean(ok)),
                          "mean_confidence": float(np.mean(conf)), "ece": expected_calibration_error(conf, ok),
                          "truth_found_percent": 100.0 * float(np.mean(found)) if found else None})
        decide = [next((i + 1 for i, s in enumerate(r[strategy]) if s["confidence"] >= 0.99), TOUCHES)
                  for r in rows]
        adds = [s["seconds"] for r in rows for s in r[strategy][1:]]
        # an add to a session of n touches, against the added touch's own recognition: a session that
        # stops early leaves its easy adds out of the pooled median, so the medians per n are reported too
        by_n, own = [], []
        for n in range(1, TOUCHES):
            ratios = [_over_own(r[strategy][n]) for r in rows if len(r[strategy]) > n]
            ratios = [x for x in ratios if x is not None]
            by_n.append({"touches_before": n, "adds": len(ratios), **_quantiles(ratios)})
            own += ratios
        out[strategy] = {"per_touches": per_k, "mean_touches_to_0.99": float(np.mean(decide)),
                         "add_seconds": _quantiles(adds),
                         "add_ratio_of_medians": float(np.median(adds) / np.median(first)) if adds else None,
                         "add_over_own": _quantiles(own), "add_over_own_by_touches": by_n,
                         "propose_seconds": _quantiles([s["propose_seconds"] for r in rows for s in r[strategy]
                                                        if "propose_seconds" in s]),
                         "add_stages": _stages([s for r in rows for s in r[strategy][1:]])}
    out["first_touch_seconds"] = _quantiles(first)
    out["sessions"] = len(rows)
    return out


def _plot(table: dict, out: Path) -> None:
    from ..plots import _plt, save_figure

    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, s in table["summary"].items():
        for strategy in table["strategies"]:
            k = [p["touches"] for p in s[strategy]["per_touches"]]
            acc = [p["accuracy_percent"] for p in s[strategy]["per_touches"]]
            ax.plot(k, acc, marker="o", ls="-" if strategy == "next" else "--", label=f"{name}, {strategy}")
    ax.axhline(99, color="grey", lw=0.8)
    ax.set_xlabel("touches")
    ax.set_ylabel("accuracy (%)")
    ax.set_xticks(range(1, TOUCHES + 1))
    ax.legend(fontsize=8)
    ax.set_title("multi-touch sessions: accuracy against touches")
    save_figure(fig, out / "multi-touch.png")
    from .calibration import reliability

    fig, ax = plt.subplots(figsize=(5, 5))
    ax.plot([0, 1], [0, 1], color="grey", lw=0.8, ls="--")
    for r in table["records_by_set"]:
        rows = table["records_by_set"][r]
        conf = [s["confidence"] for row in rows for strategy in table["strategies"] for s in row[strategy]]
        ok = [s["correct"] for row in rows for strategy in table["strategies"] for s in row[strategy]]
        bins = reliability(conf, ok)
        ax.plot([b["confidence"] for b in bins], [b["accuracy"] for b in bins], marker="o",
                label=f"{r} (ECE {expected_calibration_error(conf, ok):.3f})")
    ax.set_xlabel("confidence")
    ax.set_ylabel("accuracy")
    ax.legend(fontsize=8)
    ax.set_title("reliability over every session state")
    save_figure(fig, out / "multi-touch-reliability.png")


def _merged(records: list[dict]) -> list[dict]:
    """One row per session (set, scan, instance) with every strategy's steps, in first-seen order."""
    rows: dict = {}
    for r in records:
        rows.setdefault((r["set"], r["model"], r["instance"]), {}).update(r)
    return list(rows.values())


def run(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False, sets=SETS,
        strategies=STRATEGIES, **_ignored) -> dict:
    """Run the sessions of ``sets`` with each of ``strategies``; write ``multi-touch.json``, ``.md``
    and the plots.  Each strategy's sessions are saved apart, under a hash of the sources that
    strategy runs (an interrupted or repeated run reuses them)."""
    from ..surfaces import ycb_names

    strategies = tuple(s for s in STRATEGIES if s in strategies)
    if not strategies:
        raise ValueError(f"no strategy to run; known: {', '.join(STRATEGIES)}")
    out = Path(out)
    folders = {s: out / "multi-touch.parts" / f"{s}-{_code_hash(s)}" for s in strategies}
    for folder in folders.values():
        folder.mkdir(parents=True, exist_ok=True)
    tasks = []
    if "hard-10" in sets:
        tasks += [("hard-10", m, i, seed) for m in range(len(BUILTIN_SETS["paper-fig11"])) for i in range(instances)]
    if "p3-78" in sets:
        tasks += [("p3-78", m, i, seed) for m in range(len(ycb_names())) for i in range(math.ceil(instances / 10))]
    jobs_ = [(t + (strategy,), folders[strategy]) for t in tasks for strategy in strategies]
    records = _merged(run_parallel(_saved, jobs_, jobs=jobs or 1, quiet=quiet, desc="multi-touch"))
    by_set = {s: [r for r in records if r["set"] == s] for s in sets}
    table = {"benchmark": "multi-touch", "instances": instances, "seed": seed, "radius_mm": RADIUS,
             "strategies": list(strategies),
             "summary": {s: summary(rows, strategies) for s, rows in by_set.items() if rows}, "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "multi-touch.json", table)
    lines = [f"Sessions of up to {TOUCHES} touches (seed {seed}), method fast; accuracy (mean confidence) after "
             "each touch count.", "",
             "| set | strategy | " + " | ".join(f"{k} touch{'es' if k > 1 else ''}" for k in range(1, TOUCHES + 1))
             + " | touches to 0.99 | add s median / p95 / max | add / first, medians "
             "| add / the touch alone, median / p95 / max |",
             "|---|---|" + "---|" * (TOUCHES + 4)]
    for name, s in table["summary"].items():
        for strategy in table["strategies"]:
            st = s[strategy]
            cells = [f"{p['accuracy_percent']:.1f}% ({p['mean_confidence']:.2f})" for p in st["per_touches"]]
            a = st["add_seconds"]
            adds = "-" if a["median"] is None else f"{a['median']:.2f} / {a['p95']:.2f} / {a['max']:.2f}"
            ratio = "-" if st["add_ratio_of_medians"] is None else f"{st['add_ratio_of_medians']:.2f}"
            o = st["add_over_own"]
            own = "-" if o["median"] is None else f"{o['median']:.2f} / {o['p95']:.2f} / {o['max']:.2f}"
            lines.append(f"| {name} ({s['sessions']}) | {strategy} | " + " | ".join(cells)
                         + f" | {st['mean_touches_to_0.99']:.2f} | {adds} | {ratio} | {own} |")
    lines += ["", "Adding a touch to a session of n touches, against the added touch's own recognition: median "
              "(adds).", "", "| set | strategy | " + " | ".join(f"n = {n}" for n in range(1, TOUCHES)) + " |",
              "|---|---|" + "---|" * (TOUCHES - 1)]
    for name, s in table["summary"].items():
        for strategy in table["strategies"]:
            cells = ["-" if b["median"] is None else f"{b['median']:.2f} ({b['adds']})"
                     for b in s[strategy]["add_over_own_by_touches"]]
            lines.append(f"| {name} | {strategy} | " + " | ".join(cells) + " |")
    lines += ["", "Where the adds' time goes: per stage of an add, the adds that ran it, its share of the adds' "
              "seconds, and its seconds over the added touch's own search (median over the adds that ran it).", "",
              "| set | strategy | adds | " + " | ".join(STAGES) + " |", "|---|---|---|" + "---|" * len(STAGES)]
    for name, s in table["summary"].items():
        for strategy in table["strategies"]:
            st = s[strategy]["add_stages"]
            adds = sum(b["adds"] for b in s[strategy]["add_over_own_by_touches"])
            cells = ["-" if st[k]["share"] is None else
                     f"{st[k]['adds']}, {100 * st[k]['share']:.0f}%, "
                     + ("-" if st[k]["over_own_median"] is None else f"{st[k]['over_own_median']:.2f}")
                     for k in STAGES]
            lines.append(f"| {name} | {strategy} | {adds} | " + " | ".join(cells) + " |")
    lines += ["", "Sessions whose pose of the true model fits the touches as well as the true pose does, after "
              "each touch count (a wrong answer with the true pose found is the data's, not the searches').", "",
              "| set | strategy | " + " | ".join(str(k) for k in range(1, TOUCHES + 1)) + " |",
              "|---|---|" + "---|" * TOUCHES]
    for name, s in table["summary"].items():
        for strategy in table["strategies"]:
            cells = ["-" if p["truth_found_percent"] is None else f"{p['truth_found_percent']:.0f}%"
                     for p in s[strategy]["per_touches"]]
            lines.append(f"| {name} | {strategy} | " + " | ".join(cells) + " |")
    table["text"] = "\n".join(lines) + "\n"
    write_text_atomic(out / "multi-touch.md", table["text"])
    _plot(dict(table, records_by_set=by_set), out)
    return table
