"""Objects the database does not hold (``tactrec bench open-world``).

Leave-one-out over a scan set: every touch of ``fast-vs-paper`` (protocols
``p3`` and ``hard``, same seeds) is recognised twice with ``fast``, against
the whole set (a *known* object) and against the set without the touched scan
(an *unknown* one: the search is run among the others).  Scan sets: the ten
``paper-fig11`` scans (``fig11``) and the meshes from other sources
(:mod:`tactrec.bench.other_scans`, ``other``); on request (``--sets cad``)
the ten machined parts with sharp edges and flat faces
(:mod:`tactrec.bench.cad_parts`, ``cad``).  Sessions of left-out objects:
on each scan, ``ceil(instances / 5)`` sessions of :data:`SESSION_TOUCHES`
touches of the ``hard`` protocol at random places within reach of the
earlier ones (``multi-touch``'s ``random``), recognised against the set
without that scan.

Reported per scan set and protocol, from each record's evidence
(:class:`tactrec.probability.Evidence`, saved, so a change of the probability
model re-scores saved touches without recognising them again), at the
default prior of unknown (:data:`tactrec.probability.UNKNOWN_PRIOR`):

* unknown touches: how often ``unknown`` is the most probable outcome, and
  its median probability;
* known touches: top-1 accuracy in the open world (the most probable outcome,
  ``unknown`` included, is the touched scan) beside the closed world's (the
  best model is), and how often the touched scan's best pose fails the fit
  test (the search missed its true pose: what
  :data:`tactrec.probability.SEARCH_MISS` stands for);
* all outcomes together, known and unknown touches mixed one to one: the
  expected calibration error of the most probable outcome's probability
  (:func:`tactrec.bench.calibration.expected_calibration_error`), and how
  often an outcome at probability >= 0.95 is right;
* sessions: how often ``unknown`` reaches 0.9 within 1, 2 and 3 touches.

Each set is scored with its null model of chance fits (:mod:`tactrec.chance`,
fitted on the set's own scans by :func:`tactrec.bench.common.null_model`,
seeded apart from the touches), and again by the fit test alone
(:data:`FIT_TEST`).  A left-out scan's touches and sessions are scored with
the set's null model less the calibration touches of that scan
(:meth:`tactrec.chance.NullModel.without`): it never saw the object.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..io.atomic import write_text_atomic
from ..probability import CONSISTENT_SE, UNKNOWN_PRIOR, Evidence
from ..simulation import random_rigid_motion, sensor_to_world
from ..surfaces import BUILTIN_SETS
from .calibration import ece_if_calibrated, expected_calibration_error
from .common import (CORE_SOURCES, instance_rng, null_model, recognizer, run_parallel, saved_record, sources_hash,
                     write_json)

__all__ = ["run", "SCAN_SETS", "EXTRA_SETS", "PROTOCOLS", "SESSION_TOUCHES", "outcome", "beyond_test"]

SCAN_SETS = ("fig11", "other")
#: sets run only on request
EXTRA_SETS = ("cad",)
PROTOCOLS = ("p3", "hard")
#: touches per session of a left-out object
SESSION_TOUCHES = 3
#: the targets: unknown most probable on this share of unknown touches; sessions reaching unknown >= SURE_UNKNOWN
UNKNOWN_TARGET, SURE, SURE_UNKNOWN = 95.0, 0.95, 0.9
#: the rows scored without the null model of chance fits, by the fit test alone, beside
FIT_TEST = ", fit test alone"


def _code_hash() -> str:
    return sources_hash(*CORE_SOURCES, "session", "bench/fast_vs_paper.py", "bench/common.py", "bench/multi_touch.py",
                        "bench/open_world.py")


def _models(scans: str) -> tuple[str, ...]:
    from .cad_parts import CAD
    from .other_scans import OTHER

    if scans not in SCAN_SETS + EXTRA_SETS:
        raise ValueError(f"no scan set {scans!r}; known: {', '.join(SCAN_SETS + EXTRA_SETS)}")
    return tuple(BUILTIN_SETS["paper-fig11"]) if scans == "fig11" else CAD if scans == "cad" else OTHER


def _recognized(rec) -> dict:
    return {"recognized": rec.best, "seconds": rec.seconds, "settled": rec.settled,
            "evidence": None if rec.evidence is None else rec.evidence.to_json()}


def _touch(task) -> dict:
    from .common import database, simulate

    scans, m_index, instance, seed, protocol = task
    models = _models(scans)
    db = database(models)
    entry = db.entries[m_index]
    site, touch = simulate(entry, m_index, instance, seed, protocol)
    r = recognizer(db.entries)
    others = [m for m in models if m != entry.name]
    return {"kind": "touch", "scans": scans, "protocol": protocol, "model": entry.name, "instance": instance,
            "site": site, "known": _recognized(r.recognize(touch)),
            "unknown": _recognized(r.recognize(touch, among=others))}


def _session(task) -> dict:
    """A session of the ``hard`` protocol on scan ``m_index``, recognised without it."""
    from ..recognition import Recognizer, default_workers
    from .common import database, simulate
    from .multi_touch import SPECS, next_touch

    scans, m_index, instance, seed = task
    db = database(_models(scans))
    entry = db.entries[m_index]
    first = simulate(entry, m_index, instance, seed, "hard")[1]
    Rw, tw = random_rigid_motion(instance_rng(seed, m_index, instance, 77), extent=200.0)
    world2model = (Rw.T, -Rw.T @ tw, 1.0)
    rng = instance_rng(seed, m_index, instance, 91)
    steps = []
    with Recognizer([e for e in db.entries if e is not entry], workers=default_workers()) as r:
        session = r.session()
        touch, pose = first, sensor_to_world(first, (Rw, tw))
        while True:
            start = time.perf_counter()
            result = session.add(touch, pose)
            steps.append({"best": result.best, "seconds": time.perf_counter() - start,
                          "evidence": None if result.evidence is None else result.evidence.to_json()})
            if len(steps) >= SESSION_TOUCHES:
                break
            found = next_touch("random", session, entry, world2model, SPECS["hard-10"], rng)
            if found is None:
                break
            touch, pose = found
    return {"kind": "session", "scans": scans, "model": entry.name, "instance": instance, "steps": steps}


def _saved(job):
    task, folder = job
    name = "-".join(str(x) for x in task)
    fn = _session if len(task) == 4 else _touch
    return saved_record(folder / f"{name}.json", lambda: fn(task))


def outcome(evidence: dict | None, prior: float = UNKNOWN_PRIOR, chance=None) -> tuple[str, float, float]:
    """The most probable outcome of a saved evidence (a model's name or ``"unknown"``), its probability
    and the probability of unknown (``chance``: the database's null model of chance fits, or None)."""
    if evidence is None:
        return "unknown", 1.0, 1.0
    found = Evidence.from_json(evidence)
    p, unknown = found.outcomes(prior=prior, chance=chance)
    if len(p) and p.max() > unknown:
        k = int(np.argmax(p))
        return found.models[k], float(p[k]), unknown
    return "unknown", unknown, unknown


def beyond_test(evidence: dict | None, model: str) -> bool:
    """Whether the touched ``model``'s best pose in a saved evidence fails the fit test (more than
    :data:`~tactrec.probability.CONSISTENT_SE` standard errors beyond the noise), or it has none: the
    search missed its true pose (:data:`~tactrec.probability.SEARCH_MISS` is the share of known touches)."""
    if evidence is None:
        return True
    found = Evidence.from_json(evidence)
    z = dict(zip(found.models, found.excess().tolist()))
    return not z.get(model, np.inf) <= CONSISTENT_SE


def _percent(values) -> float | None:
    values = list(values)
    return 100.0 * float(np.mean(values)) if values else None


def _without(nulls: dict, scans: str, model: str):
    """The set's null model without the calibration touches of ``model`` (None without one): a left-out
    scan is scored by a null model that never saw it."""
    found = nulls.get(scans)
    return None if found is None else found.without([model])


def _touch_summary(rows: list[dict], prior: float, nulls: dict) -> dict:
    known = [outcome(r["known"]["evidence"], prior, nulls.get(r["scans"])) + (r["model"], r["known"]["recognized"])
             for r in rows]
    unknown = [outcome(r["unknown"]["evidence"], prior, _without(nulls, r["scans"], r["model"])) for r in rows]
    conf = [k[1] for k in known] + [u[1] for u in unknown]
    right = [k[0] == k[3] for k in known] + [u[0] == "unknown" for u in unknown]
    sure = [ok for c, ok in zip(conf, right) if c >= SURE]
    seconds = {"known": [r["known"]["seconds"] for r in rows], "unknown": [r["unknown"]["seconds"] for r in rows]}
    return {"touches": len(rows),
            "unknown_top_percent": _percent(u[0] == "unknown" for u in unknown),
            "unknown_median": float(np.median([u[2] for u in unknown])) if rows else None,
            "known_open_percent": _percent(k[0] == k[3] for k in known),
            "known_closed_percent": _percent(k[4] == k[3] for k in known),
            "known_unknown_percent": _percent(k[0] == "unknown" for k in known),
            "own_beyond_percent": _percent(beyond_test(r["known"]["evidence"], r["model"]) for r in rows),
            "ece": expected_calibration_error(conf, right), "ece_if_calibrated": ece_if_calibrated(conf),
            "sure": len(sure), "sure_right_percent": _percent(sure),
            "seconds": {k: [float(np.median(v)), float(np.percentile(v, 95)), float(np.max(v))] if v else None
                        for k, v in seconds.items()}}


def _session_summary(rows: list[dict], prior: float, nulls: dict) -> dict:
    reached, sure_wrong = [], 0
    for r in rows:
        found = [outcome(s["evidence"], prior, _without(nulls, r["scans"], r["model"])) for s in r["steps"]]
        reached.append([any(f[2] >= SURE_UNKNOWN for f in found[:n]) for n in range(1, SESSION_TOUCHES + 1)])
        sure_wrong += any(f[0] != "unknown" and f[1] >= SURE for f in found)
    return {"sessions": len(rows),
            "unknown_by_touches_percent": [_percent(x[n] for x in reached) for n in range(SESSION_TOUCHES)],
            "sure_wrong": int(sure_wrong)}


def run(*, out, instances: int = 5, seed: int = 0, jobs: int | None = None, quiet: bool = False, sets=SCAN_SETS,
        prior: float = UNKNOWN_PRIOR, **_ignored) -> dict:
    """Recognise the touches and sessions of ``sets``; write ``open-world.json`` and ``.md``."""
    out = Path(out)
    folder = out / "open-world.parts" / _code_hash()
    folder.mkdir(parents=True, exist_ok=True)
    tasks = []
    for scans in sets:
        n = len(_models(scans))
        tasks += [(scans, m, i, seed, p) for p in PROTOCOLS for m in range(n) for i in range(instances)]
        tasks += [(scans, m, i, seed) for m in range(n) for i in range(math.ceil(instances / 5))]
    records = run_parallel(_saved, [(t, folder) for t in tasks], jobs=jobs or 1, quiet=quiet, desc="open-world")
    from .common import database

    summary = {}
    for label, nulls in (("", {s: null_model(database(_models(s)).entries) for s in sets}), (FIT_TEST, {})):
        for scans in sets:
            for p in PROTOCOLS:
                rows = [r for r in records if r["kind"] == "touch" and r["scans"] == scans and r["protocol"] == p]
                summary[f"{scans}/{p}{label}"] = _touch_summary(rows, prior, nulls)
            summary[f"{scans}/sessions{label}"] = _session_summary(
                [r for r in records if r["kind"] == "session" and r["scans"] == scans], prior, nulls)
        summary[f"all touches{label}"] = _touch_summary([r for r in records if r["kind"] == "touch"], prior, nulls)
    table = {"benchmark": "open-world", "instances": instances, "seed": seed, "prior": prior,
             "targets": {"unknown_top_percent": UNKNOWN_TARGET, "sure": SURE, "session_unknown": SURE_UNKNOWN},
             "summary": summary, "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "open-world.json", table)
    table["text"] = _text(table)
    write_text_atomic(out / "open-world.md", table["text"])
    return table


def _cell(x, fmt="{:.1f}%") -> str:
    return "-" if x is None else fmt.format(x)


def _text(table: dict) -> str:
    lines = [f"Leave-one-out, fast, seed {table['seed']}, {table['instances']} touches per scan and protocol, "
             f"prior of unknown {table['prior']:g}; each set's probabilities from its null model of chance fits "
             f"(tactrec.chance, fitted on the set's own scans), and '{FIT_TEST[2:]}' by the fit test without it.", "",
             "| scans / protocol | touches | unknown most probable (left out) | median p(unknown) | "
             "top-1 open (known) | top-1 closed (known) | known called unknown | own model beyond the test | "
             "ECE (all outcomes) | "
             "ECE if calibrated | p >= 0.95 | right among them | s known (median/p95/max) | s unknown |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, s in table["summary"].items():
        if "touches" not in s:
            continue
        t = {k: "-" if v is None else "/".join(f"{x:.2f}" for x in v) for k, v in s["seconds"].items()}
        lines.append(f"| {name} | {s['touches']} | {_cell(s['unknown_top_percent'])} | "
                     f"{_cell(s['unknown_median'], '{:.3f}')} | {_cell(s['known_open_percent'])} | "
                     f"{_cell(s['known_closed_percent'])} | {_cell(s['known_unknown_percent'])} | "
                     f"{_cell(s['own_beyond_percent'])} | {s['ece']:.3f} | "
                     f"{s['ece_if_calibrated']:.3f} | {s['sure']} | {_cell(s['sure_right_percent'])} | "
                     f"{t['known']} | {t['unknown']} |")
    lines += ["", "| sessions of a left-out scan | sessions | unknown >= 0.9 within 1 / 2 / 3 touches | "
              "sure (>= 0.95) and wrong |", "|---|---|---|---|"]
    for name, s in table["summary"].items():
        if "sessions" in s:
            by = " / ".join(_cell(x) for x in s["unknown_by_touches_percent"])
            lines.append(f"| {name} | {s['sessions']} | {by} | {s['sure_wrong']} |")
    return "\n".join(lines) + "\n"
