"""Sessions of single contacts, as a probe or a force/torque sensor records them (``tactrec bench contacts``).

Each session touches one scan of a set (:data:`SETS`: the ten ``paper-fig11``
scans; ``other``, the free-form meshes of other sources,
:mod:`.other_scans`, each recognised among its set) at :data:`CONTACTS`
places uniform over its area (:func:`tactrec.simulation.simulate_contacts`),
each a point with Gaussian noise of ``noise`` mm per coordinate and an
outward normal tilted by ``normal_sd`` degrees per direction, both stated in
the contact.  The contacts are added to a :class:`~tactrec.session.Session`
one at a time, in the object's frame turned by a random pose; after each, the
session's answer and its confidence are recorded.  Sessions go round the
scans, ``instances`` per scan.

Reported: how many sessions are right at >= 0.95 within 12 contacts (the
issue's target: 95 of 100), from a count on which every later answer is too,
the median of that count, how many answers along the way were sure (>= 0.95)
and wrong, and
the seconds an add takes (median, p95, max).

Two strategies (``--strategies``): ``random``, every contact at a random
place; ``next``, each where :meth:`tactrec.session.Session.next` proposes
once the session has a hypothesis (from the third contact on), else at
random: the probe follows the proposed approach line on the true object
(within :data:`~tactrec.bench.multi_touch.RADIUS` of an earlier contact, as
the multi-touch bench's) and records a contact, with the same noise, where
it first meets the surface, or a line that met nothing
(:meth:`~tactrec.session.Session.add_miss`).  Each approach is one of the
:data:`CONTACTS` steps, whether it met the object or not.  Where nothing is
proposed (one hypothesis holds the probability) or the line starts inside the
object, the next random contact is taken.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.atomic import write_text_atomic
from .common import CORE_SOURCES, database, instance_rng, recognizer, run_parallel, saved_record, sources_hash, \
    write_json
from .sensor import _quantiles

__all__ = ["run", "SETS", "STRATEGIES", "CONTACTS", "NOISE", "NORMAL_SD", "SURE", "TARGET"]

#: the sets of scans sessions may touch (``--sets``); the first is the default
SETS = ("fig11", "other")

#: where each contact is placed (``--strategies``); the first is the default
STRATEGIES = ("random", "next")

#: contacts a session adds at most
CONTACTS = 12
#: each contact's point noise (mm, sigma per coordinate) and its normal's (degrees per direction)
NOISE = 0.1
NORMAL_SD = 5.0
#: a sure answer
SURE = 0.95
#: the issue's target: this share of sessions right at SURE within CONTACTS contacts
TARGET = 95.0


def _code_hash(strategy: str) -> str:
    """The sources a strategy's sessions run: random places never ask for a proposal."""
    proposal = ("proposal", "missed.py") if strategy == "next" else ()
    return sources_hash(*CORE_SOURCES, "simulation.py", "engine/contacts.py", "io/contacts.py", "session",
                        "bench/contacts.py", *proposal)


def _names(scans: str = SETS[0]) -> tuple[str, ...]:
    from ..surfaces import BUILTIN_SETS
    from .other_scans import OTHER

    return tuple(BUILTIN_SETS["paper-fig11"]) if scans == "fig11" else OTHER


def _proposed(session, model, truth, noise: float, normal_sd: float, rng):
    """Where ``next`` sends the probe (:func:`followed`), or None where the session has no hypothesis yet."""
    from .multi_touch import RADIUS

    try:
        proposal = session.next(radius=RADIUS, rng=rng)
    except ValueError:                                         # no hypothesis yet
        return None
    return followed(proposal, model, truth, noise, normal_sd, rng)


def followed(proposal, model, truth, noise: float, normal_sd: float, rng):
    """The probe follows ``proposal``'s approach line on the true object (``truth``, a hypothesis of
    ``model``): the contact it records where the line first meets the surface (world frame, with the
    noise stated), the line where it meets nothing, or None (nothing proposed, or the line starts inside
    the object)."""
    from ..io.contacts import Contacts
    from ..missed import first_hit, line_step
    from ..simulation import perturbed

    line = proposal.approach
    if proposal.contact is None or line is None:
        return None
    hit = first_hit(model, truth, line, line_step(0.0, line.length))
    if hit is None:
        return line
    if np.array_equal(hit, line.start):
        return None
    x = (truth.rotation @ hit + truth.translation)[None]                               # model frame
    seen, tilt = perturbed(x, model.planes(x)[1], noise=noise, normal_sd=normal_sd, rng=rng)
    return Contacts((seen - truth.translation) @ truth.rotation, tilt @ truth.rotation, np.array([normal_sd]),
                    np.array([noise]))


def _session(task) -> dict:
    """One session of ``task = (scan index, instance, seed, noise, normal_sd, set, strategy)``."""
    from ..io.session import MissedLine
    from ..io.touch import TactileData
    from ..session.result import Hypothesis
    from ..simulation import simulate_contacts, truth_pose

    m, i, seed, noise, normal_sd, scans, strategy = task
    names = _names(scans)
    db = database(names)
    entry = db.entries[m]
    rng = instance_rng(seed, m, i)
    data = simulate_contacts(entry.model, CONTACTS, noise=noise, normal_sd=normal_sd, rng=rng)
    c = data.contacts
    truth = Hypothesis("truth", *truth_pose(data), 1.0, 0.0, np.zeros(0), ())
    pick = instance_rng(seed, m, i, 79)
    session = recognizer(db.entries).session()
    steps, drawn = [], 0
    for k in range(CONTACTS):
        found = _proposed(session, entry.model, truth, noise, normal_sd, pick) if strategy == "next" else None
        proposed = found is not None
        if found is None:
            found = c.rows(slice(drawn, drawn + 1))
            drawn += 1
        if isinstance(found, MissedLine):
            result = session.add_miss(found)
        else:
            result = session.add(TactileData.from_contacts(found, units=data.units, source=f"contact {k + 1}"))
        steps.append({"best": result.best, "confidence": float(result.confidence), "unknown": float(result.unknown),
                      "seconds": float(result.seconds), "proposed": proposed, "missed": isinstance(found, MissedLine)})
    return {"model": entry.name, "instance": i, "strategy": strategy, "steps": steps}


def _saved(args) -> dict:
    task, folder = args
    m, i = task[:2]
    return saved_record(Path(folder) / f"{m}-{i}.json", lambda: _session(task))


def _summary(records: list[dict]) -> dict:
    """A session counts as right at :data:`SURE` from the first contact from which every answer is the
    touched scan at that confidence (one that is right and sure, then sure of another, is not yet);
    every sure answer of another scan, at any count, is a sure and wrong one."""
    firsts, sure_wrong, seconds = [], 0, []
    for rec in records:
        first = None
        for k, step in enumerate(rec["steps"], start=1):
            seconds.append(step["seconds"])
            sure = step["best"] is not None and step["confidence"] >= SURE
            if sure and step["best"] != rec["model"]:
                sure_wrong += 1
            right = sure and step["best"] == rec["model"]
            first = (first or k) if right else None
        firsts.append(first)
    done = [k for k in firsts if k is not None]
    return {"sessions": len(records), "right_sure": len(done),
            "right_sure_percent": 100.0 * len(done) / max(len(records), 1),
            "median_contacts": float(np.median(done)) if done else None,
            "sure_wrong_answers": sure_wrong, "add_seconds": _quantiles(seconds),
            "missed": sum(bool(step.get("missed")) for rec in records for step in rec["steps"])}


def run(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        sets=SETS[:1], strategies=STRATEGIES[:1], first: int = 0, **_ignored) -> dict:
    """Run ``instances`` sessions per scan of each of ``sets`` with each of ``strategies`` (those from
    instance ``first`` on: each session depends on its scan, instance and seed alone, so a run split
    over machines gives the sessions one run would); write ``contacts.json`` and ``contacts.md``.  Each
    strategy's sessions are saved apart, under a hash of the sources it runs (an interrupted or repeated
    run reuses them)."""
    out = Path(out)
    strategies = tuple(s for s in STRATEGIES if s in strategies)
    if not strategies:
        raise ValueError(f"no strategy to run; known: {', '.join(STRATEGIES)}")
    per_set = {}
    for scans in sets:
        for strategy in strategies:
            folder = out / "contacts.parts" / scans / f"{strategy}-{_code_hash(strategy)}"
            folder.mkdir(parents=True, exist_ok=True)
            tasks = [(m, i, seed, NOISE, NORMAL_SD, scans, strategy) for i in range(first, instances)
                     for m in range(len(_names(scans)))]
            records = run_parallel(_saved, [(t, folder) for t in tasks], jobs=jobs or 1, quiet=quiet,
                                   desc=f"contacts {scans} {strategy}")
            per_set[f"{scans} {strategy}"] = {"summary": _summary(records), "records": records}
    table = {"benchmark": "contacts", "method": "fast", "instances": instances, "first_instance": first, "seed": seed,
             "noise": NOISE, "normal_sd": NORMAL_SD, "contacts": CONTACTS, "target": TARGET, "sets": per_set}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "contacts.json", table)
    rows = []
    for scans, found in per_set.items():
        s = found["summary"]
        q = "-" if s["add_seconds"] is None else "/".join(f"{x:.2f}" for x in s["add_seconds"])
        median = "-" if s["median_contacts"] is None else f"{s['median_contacts']:g}"
        rows.append(f"| {scans} | {s['sessions']} | {s['right_sure']} ({s['right_sure_percent']:.0f}%; target "
                    f"{TARGET:g}%) | {median} | {s['sure_wrong_answers']} | {s['missed']} | {q} |")
    table["text"] = "\n".join([
        f"Sessions of up to {CONTACTS} approaches, each scan recognised among its set; point noise {NOISE} mm, "
        f"normals {NORMAL_SD} degrees, seed {seed}" + (f"; instances {first} to {instances - 1}" if first else "")
        + ".", "",
        "| set and strategy | sessions | right at >= 0.95 within 12 (and after) | median approaches to it | "
        "sure and wrong answers | approaches that met nothing | s an add (median/p95/max) |",
        "|---|---|---|---|---|---|---|", *rows])
    write_text_atomic(out / "contacts.md", table["text"])
    return table
