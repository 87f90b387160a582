"""How often the contact search misses the touched model (``tactrec bench contact-search``).

A session of single contacts is searched from its third contact on (:mod:`tactrec.engine.contacts`),
and a model whose search keeps no pose that agrees with the contacts' normals is rejected: it gets no
probability.  Where that model is the touched one, another that fits the few contacts by chance can be
called sure.  So each of ``instances`` seeded touches per scan (the first contacts of the sessions of
``tactrec bench contacts``: the same seeds, 0.1 mm, normals 5 degrees) is searched with its first
:data:`COUNTS` contacts among the touched scan alone.  Reported per set: how many of those searches
rejected it (each count apart, and which), and the seconds a search takes (median, p95, max).
"""

from __future__ import annotations

import time

from ..io.atomic import write_text_atomic
from .common import database, instance_rng, recognizer, run_parallel, write_json
from .contacts import CONTACTS, NOISE, NORMAL_SD, SETS, _names
from .sensor import _quantiles

__all__ = ["run", "COUNTS"]

#: the contacts a touch is searched with: its first three, four and five
COUNTS = (3, 4, 5)


def _searches(task) -> list[dict]:
    """The searches of one touch, ``task = (scan index, instance, seed, set)``, among its scan alone."""
    from ..io.touch import TactileData
    from ..simulation import simulate_contacts

    m, i, seed, scans = task
    entry = database(_names(scans)).entries[m]
    c = simulate_contacts(entry.model, CONTACTS, noise=NOISE, normal_sd=NORMAL_SD, rng=instance_rng(seed, m, i))
    units, c = c.units, c.contacts
    alone = recognizer([entry])
    out = []
    for n in COUNTS:
        start = time.perf_counter()
        found = alone.recognize(TactileData.from_contacts(c.rows(slice(n)), units=units, source=f"{n} contacts"))
        out.append({"model": entry.name, "instance": i, "contacts": n, "rejected": not found.ranking[0].ok,
                    "seconds": time.perf_counter() - start})
    return out


def run(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        sets=SETS[:1], **_ignored) -> dict:
    """Search ``instances`` touches per scan of each of ``sets`` with each of :data:`COUNTS` contacts;
    write ``contact-search.json`` and ``contact-search.md``."""
    from pathlib import Path

    out = Path(out)
    per_set, rows = {}, []
    for scans in sets:
        tasks = [(m, i, seed, scans) for m in range(len(_names(scans))) for i in range(instances)]
        found = [r for part in run_parallel(_searches, tasks, jobs=jobs or 1, quiet=quiet,
                                            desc=f"contact-search {scans}") for r in part]
        missed = [r for r in found if r["rejected"]]
        by_count = {n: sum(r["contacts"] == n for r in missed) for n in COUNTS}
        seconds = _quantiles([r["seconds"] for r in found])
        per_set[scans] = {"searches": len(found), "rejected": len(missed), "by_count": by_count,
                          "seconds": seconds, "records": found}
        q = "-" if seconds is None else "/".join(f"{x:.2f}" for x in seconds)
        rows.append(f"| {scans} | {len(found)} | {len(missed)} ({100.0 * len(missed) / max(len(found), 1):.1f}%) | "
                    + " / ".join(str(by_count[n]) for n in COUNTS) + f" | {q} |")
        rows += [f"|   | {r['model']} {r['instance']}, {r['contacts']} contacts | | | |" for r in missed]
    table = {"benchmark": "contact-search", "instances": instances, "seed": seed, "noise": NOISE,
             "normal_sd": NORMAL_SD, "counts": list(COUNTS), "sets": per_set}
    table["text"] = "\n".join([
        f"Touches of {', '.join(map(str, COUNTS))} contacts searched among the touched scan alone; point noise "
        f"{NOISE} mm, normals {NORMAL_SD} degrees, seed {seed}.", "",
        "| set | searches | the touched scan rejected | of 3 / 4 / 5 contacts | s a search (median/p95/max) |",
        "|---|---|---|---|---|", *rows])
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "contact-search.json", table)
    write_text_atomic(out / "contact-search.md", table["text"])
    return table
