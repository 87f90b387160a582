"""Recognition among all 78 YCB scans (``tactrec bench scale`` and ``scale-exhaustive``).

``scale``: ``instances`` P3 touches (contact at a vertex, three 24 mm curves
60 degrees apart, points every 0.3 mm, sensor frame) on every one of the 78
scans, each recognised by ``fast`` against all 78 in one database: top-1 and
top-3 accuracy, how many results are flagged ambiguous (and top-1 among the
rest), median time.  The touches on the first ten scans of a seeded order
are also recognised against the first 10, 20 and 40 scans of that order (the
touched scan always among them): how time grows with the number of models.

``scale-exhaustive``: one such touch on each of the first ``instances``
scans of that order, recognised twice: by ``fast`` and by an exhaustive
search that starts from every vertex of every scan under every 30-degree
rotation (no ranking, no pruning), both refined the same way.  The gap
between their top-1 accuracies is what ranking and pruning cost.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..surfaces import ycb_names
from .common import instance_rng, recognizer, run_parallel, saved_record, vertex_touch, write_json, ycb_database
from .fast_vs_paper import _code_hash

__all__ = ["run_scale", "run_exhaustive", "SIZES"]

SIZES = (10, 20, 40, 78)

def _order(seed: int, count: int) -> list[int]:
    return [int(i) for i in instance_rng(seed, 78_078).permutation(count)]


def _outcome(rec, name: str) -> dict:
    ok = [r.model for r in rec.ranking if r.ok]
    return {"recognized": rec.best, "rank": ok.index(name) + 1 if name in ok else None,
            "seconds": rec.seconds, "ambiguous": rec.ambiguous, "settled": rec.settled, "depth": rec.depth,
            "errors": [[r.model, r.error] for r in rec.ranking[:3] if r.ok]}


def _scale_task(task):
    m_index, instance, seed, sizes = task
    db = ycb_database()
    entries = db.entries
    order = _order(seed, len(entries))
    entry = entries[m_index]
    vertex, touch = vertex_touch(entry, m_index, instance, seed)
    record = {"model": entry.name, "vertex": vertex, "instance": instance,
              "all": _outcome(recognizer(entries).recognize(touch), entry.name)}
    if m_index in order[:10]:
        record["sizes"] = {str(k): _outcome(recognizer([entries[i] for i in order[:k]]).recognize(touch), entry.name)
                           for k in sizes if k < len(entries)}
    return record


def _exhaustive_task(task):
    m_index, seed = task
    db = ycb_database()
    entry = db.entries[m_index]
    vertex, touch = vertex_touch(entry, m_index, 0, seed)
    return {"model": entry.name, "vertex": vertex,
            "fast": _outcome(recognizer(db.entries).recognize(touch), entry.name),
            "exhaustive": _outcome(recognizer(db.entries, exhaustive=True, refine=64).recognize(touch),
                                   entry.name)}


def _saved(job):
    fn, task, path = job
    return saved_record(path, lambda: fn(task))


def _folder(out: Path, name: str) -> Path:
    folder = out / f"{name}.parts" / _code_hash()
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _accuracy(rows: list[dict]) -> dict:
    if not rows:
        return {}
    ranks = [r["rank"] for r in rows]
    clear = [r for r in rows if not r["ambiguous"]]
    return {"touches": len(rows),
            "top1_percent": 100.0 * np.mean([k == 1 for k in ranks]),
            "top3_percent": 100.0 * np.mean([k is not None and k <= 3 for k in ranks]),
            "ambiguous": len(rows) - len(clear),
            "top1_percent_unambiguous": 100.0 * np.mean([r["rank"] == 1 for r in clear]) if clear else None,
            "median_seconds": float(np.median([r["seconds"] for r in rows])),
            "p95_seconds": float(np.percentile([r["seconds"] for r in rows], 95)),
            "max_seconds": float(np.max([r["seconds"] for r in rows])),
            "unsettled": sum(not r.get("settled", True) for r in rows)}


def run_scale(*, out, instances: int = 2, seed: int = 0, jobs: int | None = None, quiet: bool = False,
              **_ignored) -> dict:
    out = Path(out)
    count = len(ycb_names())
    folder = _folder(out, "scale")
    tasks = [(m, i, seed, SIZES) for m in range(count) for i in range(instances)]
    jobs_ = [(_scale_task, t, folder / f"{t[0]}-{t[1]}-s{seed}.json") for t in tasks]
    records = run_parallel(_saved, jobs_, jobs=jobs or 1, quiet=quiet, desc="scale")
    table = {"benchmark": "scale", "models": count, "instances": instances, "seed": seed,
             "all": _accuracy([r["all"] for r in records]),
             "sizes": {str(k): _accuracy([r["sizes"][str(k)] for r in records if "sizes" in r])
                       for k in SIZES if k < count}}
    table["sizes"][str(count)] = _accuracy([r["all"] for r in records if "sizes" in r])
    table["records"] = records
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "scale.json", table)
    a = table["all"]
    lines = [f"{count} YCB scans, {instances} P3 touches each (seed {seed}), method fast:",
             f"  top-1 {a['top1_percent']:.1f}%, top-3 {a['top3_percent']:.1f}%, {a['ambiguous']} flagged ambiguous "
             f"(top-1 among the rest {a['top1_percent_unambiguous']:.1f}%), median {a['median_seconds']:.2f} s, "
             f"p95 {a['p95_seconds']:.2f} s, max {a['max_seconds']:.2f} s, {a['unsettled']} unsettled",
             "  models: " + ", ".join(f"{k}: {v['median_seconds']:.2f} s (top-1 {v['top1_percent']:.0f}%)"
                                      for k, v in table["sizes"].items() if v)]
    table["text"] = "\n".join(lines)
    return table


def run_exhaustive(*, out, instances: int = 5, seed: int = 0, jobs: int | None = None, quiet: bool = False,
                   **_ignored) -> dict:
    out = Path(out)
    count = len(ycb_names())
    folder = _folder(out, "scale-exhaustive")
    order = _order(seed, count)[:instances]
    jobs_ = [(_exhaustive_task, (m, seed), folder / f"{m}-s{seed}.json") for m in order]
    records = run_parallel(_saved, jobs_, jobs=jobs or 1, quiet=quiet, desc="scale-exhaustive")
    table = {"benchmark": "scale-exhaustive", "models": count, "touches": len(records), "seed": seed,
             "fast": _accuracy([r["fast"] for r in records]),
             "exhaustive": _accuracy([r["exhaustive"] for r in records]), "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "scale-exhaustive.json", table)
    f, e = table["fast"], table["exhaustive"]
    table["text"] = (f"{len(records)} P3 touches against all {count} YCB scans: top-1 fast {f['top1_percent']:.0f}% "
                     f"({f['median_seconds']:.2f} s), exhaustive {e['top1_percent']:.0f}% "
                     f"({e['median_seconds']:.0f} s); top-3 {f['top3_percent']:.0f}% / {e['top3_percent']:.0f}%")
    return table
