"""Protocols P1 and P2: the paper's closed-form simulations (Tables 2 and 3, Fig. 8).

P1 (``paper-table2``): on each surface of Table 1, ``instances`` touches at
random locations (61 points per curve, uniform noise +/-0.001, a random rigid
motion into the sensor's frame), each registered onto its own surface; the
table gives min, max and mean ``|p - p*|`` per surface.  Because the data
arrive in the sensor's frame, a touch registers equally well at any image of
its location under the surface's symmetries (the ellipsoid's half-turns, the
saddle's third-turns, ...), so ``|p - p*|`` is measured to the nearest image.

P2 (``paper-table3``): the same touches recognised against all four surfaces;
the table counts successes decided by the lookup alone (every other model
rejected for want of candidates) and by the local search, and the mean excess
of the wrong models' errors over the right one's.

Curve spacing is not given in the paper; we use 0.02 (curves 1.2 long on
surfaces about 2 across), adjacent planes 60 degrees apart, ``outward`` given.
``options`` are the ``paper`` method's readings (``parabola_points``, ...);
the output's name lists them.
"""

from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np

from ..database import build_entries
from ..recognition import recognize
from ..simulation import simulate_random_touch
from ..surfaces import BUILTIN_SETS
from .common import default_jobs, instance_rng, paper_options, paper_values, readings_text, run_parallel, write_json

__all__ = ["run_table2", "run_table3", "CONFIG"]

SURFACES = BUILTIN_SETS["paper-table1"]
CONFIG = {"points": 61, "spacing": 0.02, "angle": 60.0, "noise": 0.001, "noise_kind": "uniform"}

@functools.lru_cache(maxsize=1)
def _database():
    """The four surfaces with their tables, kept for the rest of this process."""
    return build_entries(SURFACES)


def _touch(task):
    """Simulate one instance and recognise it (against one or all surfaces)."""
    surface_index, instance, seed, method, only_own, options = task
    db = _database()
    entry = db.entries[surface_index]
    rng = instance_rng(seed, surface_index, instance)
    data = simulate_random_touch(entry.model, rng=rng, **CONFIG)
    entries = [entry] if only_own else db.entries
    start = time.perf_counter()
    result = recognize(data, entries, method=method, **dict(options))
    seconds = time.perf_counter() - start
    truth = data.meta["truth"]
    own = next(r for r in result.ranking if r.model == entry.name)
    record = {
        "surface": entry.name, "instance": instance, "true_site": truth["site"], "true_contact": truth["contact"],
        "recognized": result.best, "correct": result.best == entry.name, "seconds": seconds,
        "curvatures": [result.estimate.k1, result.estimate.k2],
        "models": {r.model: {"error": r.error if r.ok else None, "candidates": r.candidates, "rejected": r.rejected}
                   for r in result.ranking},
    }
    if own.ok:
        model = entry.model
        record["location"] = own.location.tolist()
        record["location_error"] = model.location_error(own.location, truth["contact"])
        # the estimate mapped to the symmetric image nearest the truth, for Fig. 8
        images = own.location @ model.symmetries  # g^T p for every symmetry g
        nearest = images[np.argmin(np.linalg.norm(images - np.asarray(truth["contact"]), axis=1))]
        record["estimated_site"] = model.locate(nearest).tolist()
    else:
        record["location_error"] = None
    return record


def _run(*, instances: int, seed: int, jobs: int | None, quiet: bool, method: str, only_own: bool, desc: str,
         options: tuple = ()):
    tasks = [(s, i, seed, method, only_own, options) for s in range(len(SURFACES)) for i in range(instances)]
    return run_parallel(_touch, tasks, jobs=jobs or default_jobs(), quiet=quiet, desc=desc)


def _fig8(records, out: Path, name: str) -> Path:
    from ..plots import pyplot, plot_uv_locations, save_figure

    plt = pyplot()
    db = _database()
    fig, axes = plt.subplots(1, len(SURFACES), figsize=(4 * len(SURFACES), 4))
    for ax, entry in zip(axes, db.entries):
        rows = [r for r in records if r["surface"] == entry.name and r.get("estimated_site")]
        plot_uv_locations(entry.model, [r["true_site"] for r in rows], [r["estimated_site"] for r in rows], ax=ax)
    axes[0].legend(loc="lower left", fontsize=8)
    path = out / f"{name}-fig8.png"
    save_figure(fig, path)
    return path


def _table(table: str, only_own: bool, *, out, instances: int, seed: int, jobs, quiet: bool, method: str,
           options: dict | None):
    """What Table 2 and Table 3 both start from: the output folder, the method's readings, the output's
    stem, the records of the touches (each recognised against its own surface alone, ``only_own``, or
    all four) and the paper's values of ``table``."""
    options, suffix = paper_options(options, method)
    stem = f"paper-{table}{suffix}"
    records = _run(instances=instances, seed=seed, jobs=jobs, quiet=quiet, method=method, only_own=only_own,
                   desc=stem, options=options)
    return Path(out), options, stem, records, paper_values()[table]


def run_table2(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
               method: str = "paper", options: dict | None = None) -> dict:
    """P1: localisation error per surface (paper Table 2 and Fig. 8)."""
    out, options, stem, records, paper = _table("table2", True, instances=instances, seed=seed, jobs=jobs,
                                                quiet=quiet, method=method, options=options, out=out)
    rows = {}
    for name in SURFACES:
        errs = np.array([r["location_error"] if r["location_error"] is not None else np.inf
                         for r in records if r["surface"] == name])
        times = [r["seconds"] for r in records if r["surface"] == name]
        rows[name] = {"min": float(errs.min()), "max": float(errs.max()), "mean": float(errs.mean()),
                      "failed": int(np.sum(~np.isfinite(errs))), "median_seconds": float(np.median(times)),
                      "paper": paper[name]}
    table = {"benchmark": stem, "method": method, "options": dict(options), "instances": instances, "seed": seed,
             "config": CONFIG, "surfaces": rows, "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{stem}.json", table)
    table["plots"] = [str(_fig8(records, out, stem))]
    # Table 2's and Table 3's printed tables are alike in shape by design, each with the paper's columns
    lines = [f"P1 / Table 2: |p - p*| over {instances} instances per surface "
             f"(method {method}{readings_text(options)}, seed {seed})",
             f"{'surface':22s} {'min':>8s} {'max':>8s} {'mean':>8s}   paper: {'min':>7s} {'max':>7s} {'mean':>7s}"
             f"  {'s/touch':>7s}"]
    for name, r in rows.items():
        p = r["paper"]
        lines.append(f"{name:22s} {r['min']:8.4f} {r['max']:8.4f} {r['mean']:8.4f}          {p['min']:7.4f} "
                     f"{p['max']:7.4f} {p['mean']:7.4f}  {r['median_seconds']:7.2f}")
    table["text"] = "\n".join(lines)
    return table


def run_table3(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
               method: str = "paper", options: dict | None = None) -> dict:
    """P2: recognition among the four surfaces (paper Table 3)."""
    out, options, stem, records, paper = _table("table3", False, instances=instances, seed=seed, jobs=jobs,
                                                quiet=quiet, method=method, options=options, out=out)
    rows = {}
    excess = []
    for name in SURFACES:
        recs = [r for r in records if r["surface"] == name]
        lookup = search = 0
        for r in recs:
            others = [m for m in r["models"] if m != name]
            if r["correct"]:
                if all(r["models"][m]["rejected"] == "no candidates" for m in others):
                    lookup += 1
                else:
                    search += 1
            right = r["models"][name]["error"]
            if right:
                excess += [100.0 * (r["models"][m]["error"] - right) / right for m in others
                           if r["models"][m]["error"] is not None]
        rows[name] = {"instances": len(recs), "correct": lookup + search, "lookup": lookup, "search": search,
                      "median_seconds": float(np.median([r["seconds"] for r in recs])),
                      "paper": paper[name]}
    total = sum(r["correct"] for r in rows.values())
    n = sum(r["instances"] for r in rows.values())
    table = {"benchmark": stem, "method": method, "options": dict(options), "instances": instances, "seed": seed,
             "config": CONFIG, "surfaces": rows, "correct": total, "total": n,
             "accuracy": total / n if n else 0.0,
             "wrong_model_error_excess_percent": float(np.mean(excess)) if excess else None,
             "median_seconds": float(np.median([r["seconds"] for r in records])),
             "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{stem}.json", table)
    table["plots"] = [str(_fig8(records, out, stem))]
    # alike in shape to Table 2's printed table by design, with Table 3's columns
    lines = [f"P2 / Table 3: recognition among {len(SURFACES)} surfaces, {instances} instances each "
             f"(method {method}{readings_text(options)}, seed {seed})",
             f"{'surface':22s} {'correct':>8s} {'lookup':>7s} {'search':>7s}   paper: {'lookup':>6s} {'search':>6s}"
             f"  {'s/touch':>7s}"]
    for name, r in rows.items():
        p = r["paper"]
        lines.append(f"{name:22s} {r['correct']:5d}/{r['instances']:<3d}{r['lookup']:7d} {r['search']:7d}"
                     f"           {p['lookup']:6d} {p['search']:6d}  {r['median_seconds']:7.2f}")
    ex = table["wrong_model_error_excess_percent"]
    lines.append(f"total {total}/{n} correct ({100.0 * total / max(n, 1):.1f}%); wrong models' errors "
                 f"{'n/a' if ex is None else f'{ex:.0f}%'} above the right one's (paper: "
                 f"{paper['wrong_model_error_excess_percent']}%); median {table['median_seconds']:.2f} s per touch")
    table["text"] = "\n".join(lines)
    return table
