"""``fast`` against ``paper`` on the same touches, in one run.

Two protocols on the ten YCB scans of Fig. 11 (millimetres), ``instances``
touches per scan each, every touch recognised by both methods against all ten:

``p3``
    The paper's P3 at its defaults: the contact at a vertex (no two within 15
    rings), three curves 24 mm long, planes 60 degrees apart, points every
    0.3 mm, no noise, the outward side known.
``hard``
    The contact anywhere on a face (random face, random barycentric point),
    curves 12 mm long, planes 30 degrees apart, Gaussian noise of sigma
    0.05 mm on every coordinate, the outward side unknown.

Both get a random rigid motion (the sensor frame).  Touches run one after
another by default (``jobs = 1``): each recognition has both cores, as a
user's would.  For each protocol and
method the JSON has the success rate, median and mean seconds per
recognition, and the median distance from the reported contact to the true
one; the speed-up is the ratio of the medians.  Records are saved per touch,
so an interrupted run resumes.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..probability import fit_limit
from ..recognition import FLOOR
from .common import (CORE_SOURCES, PROTOCOLS, SPACING, database, recognizer, run_parallel, saved_record, scan_set,
                     simulate, sources_hash, write_json)

__all__ = ["run", "PROTOCOLS", "SPACING", "METHODS", "scan_set"]

METHODS = ("fast", "paper")
#: a right answer is located when its contact lies this near the truth (mm), or its pose fits as well as
#: the truth's (a symmetric object's other places)
LOCATED_MM = 1.0
#: the paper's P3 at its defaults (Fig. 11)
PAPER = {"success_percent": 93, "seconds": 115}

def _touch(task):
    models, m_index, instance, seed, protocol, methods = task
    db = database(models)
    entry = db.entries[m_index]
    site, touch = simulate(entry, m_index, instance, seed, protocol)
    truth = np.asarray(touch.meta["truth"]["contact"])
    results = {}
    for method in methods:
        start = time.perf_counter()
        try:
            rec = recognizer(db.entries, method=method).recognize(touch)
        except InputError as exc:
            results[method] = {"recognized": None, "correct": False, "seconds": time.perf_counter() - start,
                               "failed": str(exc)}
            continue
        reg = rec.registration
        results[method] = {
            "recognized": rec.best, "correct": rec.best == entry.name, "seconds": rec.seconds,
            "error": reg.error if reg else None,
            "location_error": float(np.linalg.norm(reg.location - truth)) if reg and rec.best == entry.name
            else None,
            "runner_up": [rec.ranking[1].model, rec.ranking[1].error] if len(rec.ranking) > 1 and
            rec.ranking[1].ok else None,
            "ambiguous": rec.ambiguous, "settled": rec.settled, "depth": rec.depth,
            # a pose as good as the truth's (within the fit limit): on a symmetric object, another place
            # the data cannot tell from the true one
            "fits": bool(reg is not None and rec.touch is not None
                         and reg.error / reg.scale <= fit_limit(rec.touch, FLOOR)),
        }
    return {"model": entry.name, "protocol": protocol, "instance": instance, "site": site, "results": results}


def _code_hash() -> str:
    """Hash of the sources a record depends on."""
    return sources_hash(*CORE_SOURCES, "bench/fast_vs_paper.py", "bench/common.py")


def _touch_saved(job):
    task, folder = job
    models, m_index, instance, seed, protocol, methods = task
    return saved_record(folder / f"{protocol}-{models[m_index]}-{instance}-s{seed}.json", lambda: _touch(task),
                        accept=lambda saved: set(methods) <= set(saved["results"]))


def _summary(records: list[dict], protocol: str, method: str) -> dict:
    rows = [r["results"][method] for r in records if r["protocol"] == protocol and method in r["results"]]
    if not rows:
        return {}
    located = [r["location_error"] for r in rows if r.get("location_error") is not None]
    near = [r["correct"] and (r["location_error"] <= LOCATED_MM or r.get("fits", False)) for r in rows]
    return {"touches": len(rows),
            "success_percent": 100.0 * float(np.mean([r["correct"] for r in rows])),
            "unsettled": int(sum(not r.get("settled", True) for r in rows)),
            "no_fit": int(sum(not r.get("fits", False) for r in rows)),
            "sure_wrong": int(sum(not r["correct"] and r.get("ambiguous") is False for r in rows)),
            "located_percent": 100.0 * float(np.mean(near)),
            "median_seconds": float(np.median([r["seconds"] for r in rows])),
            "p95_seconds": float(np.percentile([r["seconds"] for r in rows], 95)),
            "max_seconds": float(np.max([r["seconds"] for r in rows])),
            "mean_seconds": float(np.mean([r["seconds"] for r in rows])),
            "median_location_error_mm": float(np.median(located)) if located else None,
            "misses": [(rec["model"], rec["site"], rec["results"][method]["recognized"]) for rec in records
                       if rec["protocol"] == protocol and method in rec["results"]
                       and not rec["results"][method]["correct"]]}


def run(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        models: tuple[str, ...] | None = None, protocols=tuple(PROTOCOLS), methods=METHODS, scans: str | None = None,
        **_ignored) -> dict:
    """Run both methods on the same touches; write ``fast-vs-paper.json``, ``.md`` and ``.png`` (with
    ``scans="other"``, on the meshes of :mod:`tactrec.bench.other_scans`: ``fast-vs-paper-other.*``)."""
    out = Path(out)
    models, name = scan_set(models, scans, "fast-vs-paper")
    tasks = [(models, m, i, seed, p, tuple(methods)) for p in protocols for m in range(len(models))
             for i in range(instances)]
    parts = out / "fast-vs-paper.parts" / _code_hash()
    parts.mkdir(parents=True, exist_ok=True)
    records = run_parallel(_touch_saved, [(t, parts) for t in tasks], jobs=jobs or 1, quiet=quiet,
                           desc="fast-vs-paper")
    table = {"benchmark": name, "scans": scans or "shipped", "instances": instances, "seed": seed,
             "models": list(models),
             "protocols": {p: PROTOCOLS[p] for p in protocols}, "paper_p3": PAPER,
             "summary": {p: {m: _summary(records, p, m) for m in methods} for p in protocols}}
    for p in protocols:
        s = table["summary"][p]
        if "fast" in s and "paper" in s and s["fast"] and s["paper"]:
            s["speedup_of_medians"] = s["paper"]["median_seconds"] / s["fast"]["median_seconds"]
    table["records"] = records
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{name}.json", table)
    markdown = _markdown(table)
    (out / f"{name}.md").write_text(markdown, encoding="utf-8")
    table["plots"] = [str(_plot(table, out, name))]
    table["text"] = markdown
    return table


def _markdown(table: dict) -> str:
    kind = {"other": "meshes from other sources", "cad": "machined parts made by code"}.get(table.get("scans"),
                                                                                            "YCB scans")
    lines = [f"{len(table['models'])} {kind}, {table['instances']} touches each per protocol (seed "
             f"{table['seed']}); both methods on the same touches.", "",
             "| protocol | method | success | sure and wrong | no fit | unsettled | located | median s | p95 s | max s | "
             "mean s | median contact error (mm) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for p, by_method in table["summary"].items():
        for m, s in by_method.items():
            if not isinstance(s, dict) or not s:
                continue
            loc = s["median_location_error_mm"]
            lines.append(f"| {p} | {m} | {s['success_percent']:.0f}% | {s.get('sure_wrong', '-')} | "
                         f"{s.get('no_fit', '-')} | "
                         f"{s.get('unsettled', '-')} | "
                         f"{s['located_percent']:.0f}% | {s['median_seconds']:.3g} | "
                         f"{s['p95_seconds']:.3g} | {s['max_seconds']:.3g} | {s['mean_seconds']:.3g} | "
                         f"{'-' if loc is None else f'{loc:.3f}'} |")
        if "speedup_of_medians" in by_method:
            lines.append(f"| {p} | paper / fast | | | | | | {by_method['speedup_of_medians']:.0f}x | | | | |")
    lines.append(f"| p3 | the paper's own (Fig. 11) | {PAPER['success_percent']}% | | | | | {PAPER['seconds']} | | | "
                 "| |")
    lines += ["", "sure and wrong: a wrong answer at confidence >= 0.95 (not flagged ambiguous); no fit: the "
              "answer's pose lies beyond the fit limit (the data's noise, or 1e-3 x the touch's radius "
              "on noise-free data); unsettled: the search ended on its budget; located: right, and the contact within "
              f"{LOCATED_MM:g} mm of the truth or on a pose that fits as well (a symmetric object's other places)."]
    return "\n".join(lines) + "\n"


def _plot(table, out: Path, name: str = "fast-vs-paper") -> Path:
    from ..plots import pyplot, save_figure

    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    protocols = list(table["summary"])
    methods = [m for m in METHODS if any(table["summary"][p].get(m) for p in protocols)]
    width = 0.8 / max(1, len(methods))
    for k, m in enumerate(methods):
        xs = np.arange(len(protocols)) + (k - (len(methods) - 1) / 2) * width
        ys = [table["summary"][p].get(m, {}).get("success_percent", 0.0) for p in protocols]
        axes[0].bar(xs, ys, width, label=m)
        for x, y in zip(xs, ys):
            axes[0].annotate(f"{y:.0f}%", (x, y), ha="center", va="bottom", fontsize=8)
        times = [[r["results"][m]["seconds"] for r in table["records"] if r["protocol"] == p and m in r["results"]]
                 for p in protocols]
        axes[1].boxplot(times, positions=xs, widths=width * 0.9, showfliers=False,
                        patch_artist=True, boxprops={"facecolor": f"C{k}"}, medianprops={"color": "k"})
    axes[0].axhline(table["paper_p3"]["success_percent"], color="gray", ls="--", lw=1, label="paper P3 (Fig. 11)")
    axes[0].set_xticks(range(len(protocols)), protocols)
    axes[0].set_ylabel("correct (%)")
    axes[0].set_ylim(0, 105)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[1].set_yscale("log")
    axes[1].set_xticks(range(len(protocols)), protocols)
    axes[1].set_ylabel("seconds per recognition (10 models)")
    fig.suptitle("fast vs paper, same touches")
    fig.tight_layout()
    path = out / f"{name}.png"
    save_figure(fig, path)
    return path
