"""The answers themselves, for a change that must leave them alone (``tactrec bench answers``).

A refactor, a new kernel or a library upgrade should change no answer.  This
benchmark recognises a fixed, seeded set of touches and runs a fixed set of
sessions, and writes each one's JSON (``tactrec recognize --json``'s result,
a session's result after each touch and ``next``'s proposal) with the
timings left out, and a digest of each (SHA-256 of its canonical JSON).
Two runs are compared by :func:`compare` (``tactrec bench answers
--against FILE``): the entries whose JSON differs, and the first field that
differs in each.

The set reaches every path from a touch to a result: 50 recognitions and 5
sessions.

* 15 P3 touches (a vertex, three 24 mm curves 60 degrees apart, no noise,
  outward side known) and 10 hard ones (anywhere on a face, 12 mm, 30
  degrees, Gaussian noise 0.05 mm, no outward side) of the ten ``paper-fig11``
  scans, against the 18 built-in models (the scans and the closed-form
  surfaces), method ``fast``;
* 5 touches of the closed-form surfaces of paper Table 1 against them alone;
* 5 P3 touches of the machined parts (:mod:`tactrec.bench.cad_parts`),
  their null model of chance fits calibrated on a few touches;
* 5 touches a sensor spoils (:mod:`tactrec.sensor`): a round tip, outliers,
  curves that miss each other, uneven steps, a bent stroke;
* 5 touches with method ``paper`` and 5 ``fast`` touches searched on a small
  budget (a search that does not settle);
* sessions: three of hard touches at random places on a scan, one with a line
  that met nothing, one of tip touches on the machined parts, each with
  ``next``'s proposal after every touch.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from .common import instance_rng, random_face_site, random_site_touch, write_json

__all__ = ["run", "compare", "digest", "without_timings", "P3", "HARD"]

SPACING = 0.3
P3 = dict(points=81, spacing=SPACING, angle=60.0, noise=0.0, outward=True)
HARD = dict(points=41, spacing=SPACING, angle=30.0, noise=0.05, noise_kind="gaussian", outward=False)
#: what a result holds that is a timing, not an answer
TIMINGS = ("seconds", "stages", "own_seconds")


def without_timings(value):
    """``value`` (a result's JSON) without its timings, numbers as JSON writes them."""
    if isinstance(value, dict):
        return {k: without_timings(v) for k, v in value.items() if k not in TIMINGS}
    if isinstance(value, (list, tuple)):
        return [without_timings(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return without_timings(value.tolist())
    return value


def digest(value) -> str:
    """SHA-256 of ``value``'s canonical JSON (sorted keys, full precision)."""
    return hashlib.sha256(json.dumps(value, sort_keys=True, allow_nan=True).encode()).hexdigest()


def _recognitions(seed: int):
    """``(name, database key, how its touch is made, options)`` of the 50 recognitions."""
    from ..sensor import Imperfections
    from ..surfaces import BUILTIN_SETS

    scans = BUILTIN_SETS["paper-fig11"]
    out = []
    for k in range(15):
        out.append((f"p3-{k}", "builtin", ("scan", scans[k % 10], "p3", k), {}))
    for k in range(10):
        out.append((f"hard-{k}", "builtin", ("scan", scans[k], "hard", k), {}))
    for k in range(5):
        name = BUILTIN_SETS["paper-table1"][k % 4]
        out.append((f"closed-form-{k}", "table1", ("closed", name, k), {}))
    for k in range(5):
        out.append((f"cad-{k}", "cad", ("cad", k), {}))
    spoilt = [Imperfections(tip_radius=1.0), Imperfections(outliers=0.04), Imperfections(miss=0.3),
              Imperfections(uneven=2.0, jitter=0.01), Imperfections(bend=0.2)]
    for k, imperfections in enumerate(spoilt):
        out.append((f"sensor-{k}", "builtin", ("sensor", scans[(3 * k) % 10], imperfections, k), {}))
    for k in range(5):
        out.append((f"paper-{k}", "builtin", ("scan", scans[(2 * k + 1) % 10], "p3", 20 + k), {"method": "paper"}))
    for k in range(5):
        out.append((f"budget-{k}", "builtin", ("scan", scans[(7 * k + 2) % 10], "hard", 30 + k), {"budget": 20_000}))
    return out


def _touch(spec, entries: dict, seed: int):
    from ..simulation import simulate_random_touch

    kind = spec[0]
    if kind == "scan":
        _, name, protocol, k = spec
        rng = instance_rng(seed, 1, k, 0 if protocol == "p3" else 1)
        return random_site_touch(entries["builtin"][name].model, rng, P3 if protocol == "p3" else HARD,
                                 vertex=protocol == "p3")
    if kind == "closed":
        _, name, k = spec
        return simulate_random_touch(entries["table1"][name].model, spacing=0.02, points=41, noise=0.001,
                                     rng=instance_rng(seed, 2, k))
    if kind == "cad":
        (_, k), models = spec, list(entries["cad"].values())
        rng = instance_rng(seed, 3, k)
        return random_site_touch(models[(3 * k) % len(models)].model, rng, P3, vertex=True)
    _, name, imperfections, k = spec
    model = entries["builtin"][name].model
    return random_site_touch(model, instance_rng(seed, 4, k), dict(P3, outward=False), imperfections=imperfections)


def _databases():
    from ..database import Database, cached_database
    from ..surfaces import BUILTIN_SETS
    from .cad_parts import CAD
    from .other_scans import other_database

    builtin = cached_database(BUILTIN_SETS["builtin"], name="builtin", quiet=True)
    table1 = Database([e for e in builtin.entries if e.name in BUILTIN_SETS["paper-table1"]])
    cad = other_database(CAD)
    return {"builtin": builtin, "table1": table1, "cad": cad}


def _sessions(recognizers: dict, dbs: dict, seed: int) -> dict:
    """The five sessions: each touch's result and ``next``'s proposal after it."""
    from ..io.session import MissedLine
    from ..linalg import norm3, rotate
    from ..sensor import Imperfections
    from ..simulation import random_rigid_motion, sensor_to_world, simulate_touch
    from ..surfaces import BUILTIN_SETS

    scans = BUILTIN_SETS["paper-fig11"]
    plans = [("builtin", scans[1], 0.0, False), ("builtin", scans[4], 0.0, False), ("builtin", scans[8], 0.0, False),
             ("builtin", scans[6], 0.0, True), ("cad", "l_bracket", 1.0, False)]
    out = {}
    for k, (db, name, tip, miss) in enumerate(plans):
        by_name = {e.name: e for e in dbs[db].entries}
        entry = by_name.get(name) or dbs[db].entries[k % len(dbs[db].entries)]
        model = entry.model
        rng = instance_rng(seed, 5, k)
        model2world = random_rigid_motion(rng, extent=200.0)
        session = recognizers[db].session()
        imperfections = Imperfections(tip_radius=tip) if tip else None
        steps, touches = [], 0
        for _ in range(60):
            if touches >= 3:
                break
            try:
                data = simulate_touch(model, random_face_site(model, rng), imperfections=imperfections, rng=rng, **HARD)
            except ValueError:
                continue
            result = session.add(data, sensor_to_world(data, model2world))
            touches += 1
            proposal = session.next(radius=40.0, angle=30.0, rng=instance_rng(seed, 6, k, touches))
            steps.append({"result": without_timings(result.to_json()), "next": without_timings(proposal.to_json())})
            if miss and touches == 1:
                Rw, tw = model2world
                normal = rotate(Rw, np.asarray(data.meta["truth"]["normal"], dtype=np.float64))
                contact = rotate(Rw, np.asarray(data.meta["truth"]["contact"], dtype=np.float64)) + tw
                side = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
                line = MissedLine(contact + 30.0 * normal + 20.0 * side / norm3(side), -normal, 60.0)
                steps.append({"missed": without_timings(session.add_miss(line).to_json())})
        out[f"session-{k}-{entry.name}"] = steps
    return out


def run(*, out, instances: int = 1, seed: int = 0, jobs: int | None = None, quiet: bool = False, against=None,
        **_ignored) -> dict:
    """Recognise the set's touches and run its sessions; write ``answers.json`` (each entry's JSON and
    digest) and ``answers.md``."""
    from ..chance.fit import calibrate
    from ..recognition import Recognizer, default_workers
    from ..io.atomic import write_text_atomic

    out = Path(out)
    dbs = _databases()
    entries = {key: {e.name: e for e in db.entries} for key, db in dbs.items()}
    recognizers = {key: Recognizer(db.entries, workers=default_workers()) for key, db in dbs.items()}
    answers = {}
    try:
        chance = calibrate(recognizers["cad"], touches=4, seed=seed)
        recognizers["cad"].close()
        recognizers["cad"] = Recognizer(dbs["cad"].entries, workers=default_workers(), chance=chance)
        budgeted = {}
        for name, db, spec, options in _recognitions(seed):
            touch = _touch(spec, entries, seed)
            if options:
                key = (db, tuple(sorted(options.items())))
                if key not in budgeted:
                    budgeted[key] = Recognizer(dbs[db].entries, workers=default_workers(), **options)
                rec = budgeted[key].recognize(touch)
            else:
                rec = recognizers[db].recognize(touch)
            answers[name] = without_timings(rec.to_json())
        for r in budgeted.values():
            r.close()
        answers.update(_sessions(recognizers, dbs, seed))
    finally:
        for r in recognizers.values():
            r.close()
    digests = {name: digest(value) for name, value in answers.items()}
    table = {"benchmark": "answers", "seed": seed, "digest": digest(answers), "digests": digests,
             "answers": answers}
    lines = [f"# answers (seed {seed}): {len(answers)} entries, digest {table['digest'][:16]}", ""]
    if against is not None:                        # another run's answers.json, read (tactrec bench --against)
        differ = compare(table, against)
        table["differ"] = differ
        lines.append(f"against the run given: {len(differ)} of {len(answers)} entries differ")
        lines += [f"- {name}: {where}" for name, where in differ.items()]
    table["text"] = "\n".join(lines) + "\n"
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "answers.json", {k: v for k, v in table.items() if k != "text"})
    write_text_atomic(out / "answers.md", table["text"])
    return table


def _first_difference(a, b, path: str = "") -> str | None:
    if type(a) is not type(b):
        return f"{path or '.'}: {a!r} against {b!r}"
    if isinstance(a, dict):
        for key in sorted(set(a) | set(b)):
            if key not in a or key not in b:
                return f"{path}.{key}: only in {'this run' if key in a else 'the other'}"
            found = _first_difference(a[key], b[key], f"{path}.{key}")
            if found:
                return found
        return None
    if isinstance(a, list):
        if len(a) != len(b):
            return f"{path}: {len(a)} items against {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            found = _first_difference(x, y, f"{path}[{i}]")
            if found:
                return found
        return None
    return None if a == b or (a != a and b != b) else f"{path}: {a!r} against {b!r}"


def compare(table: dict, other: dict) -> dict:
    """The entries of ``table`` whose JSON differs from ``other``'s (another run's ``answers.json``), each
    with the first field that differs; entries only one of them holds are listed too."""
    mine, theirs = table["answers"], other["answers"]
    differ = {}
    for name in sorted(set(mine) | set(theirs)):
        if name not in mine or name not in theirs:
            differ[name] = "only in " + ("this run" if name in mine else "the other")
        elif table["digests"][name] != other["digests"][name]:
            differ[name] = _first_difference(mine[name], theirs[name]) or "digests differ"
    return differ
