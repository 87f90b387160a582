"""Protocol P3: recognition on the ten YCB scans, the paper's Fig. 11.

Ten scans in millimetres; ``instances`` touches per scan at random vertices
no two within 15 rings (Section 5.4); three planes perpendicular to the
tangent plane, ``phi`` apart; points every 0.3 mm over a length ``l``;
recognition by the paper's mesh method against all ten.  Three sweeps around
the defaults ``delta = 0.03 /mm``, ``l = 24 mm``, ``phi = 60 deg``: ``delta``
in 0.005..0.03, ``l`` in 9..24 mm, ``phi`` in 10..60 degrees.

``options`` are the ``paper`` method's (:class:`tactrec.methods.paper.PaperConfig`):
its readings of the paper, such as ``parabola_points`` and ``phi_step``.

The greedy walk from one candidate does not depend on the other candidates,
so one recognition at the largest ``delta`` gives every smaller ``delta``
too: its candidates are a subset, its error the minimum over the subset's
walks, its time the recognition's time per evaluated vertex times the
vertices the subset's walks evaluate.  The ``l`` and ``phi`` sweeps need touches
of their own.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..estimation import estimate
from ..methods.paper import PaperConfig
from ..registration import mesh_paper
from ..simulation import simulate_touch, spread_vertices
from ..surfaces import BUILTIN_SETS
from .common import (CORE_SOURCES, SCANS, default_jobs, instance_rng, paper_options, run_parallel, saved_record,
                     scan_database, sources_hash, write_json)

__all__ = ["run_fig11", "SWEEPS", "DEFAULTS", "p3_touch"]

SPACING = 0.3
DEFAULTS = {"delta": 0.03, "length": 24.0, "angle": 60.0}
SWEEPS = {
    "delta": [0.005, 0.01, 0.015, 0.02, 0.025, 0.03],
    "length": [9.0, 12.0, 15.0, 18.0, 21.0, 24.0],
    "angle": [10.0, 20.0, 30.0, 40.0, 50.0, 60.0],
}
#: the paper's Fig. 11 end points (its intermediate values are not legible in the text we have)
PAPER = {"delta": {"0.005": {"success": 37, "seconds": 4}, "0.03": {"success": 93, "seconds": 115}},
         "length": {"9": {"success": 63}, "24": {"success": 93}},
         "angle": {"10": {"success": 69}, "60": {"success": 93}}}

def p3_touch(model, m_index: int, instance: int, *, seed: int, length: float, angle: float):
    """Touch ``instance`` of P3 on ``model`` (the ``m_index``-th scan): ``(vertex, data)``, the
    touched vertex (no two instances within 15 rings) and three curves through it, in a random
    sensor frame."""
    vertices = spread_vertices(model, instance + 1, rings=15, rng=instance_rng(seed, m_index))
    vertex = int(vertices[min(instance, len(vertices) - 1)])
    points = int(round(length / SPACING)) + 1
    return vertex, simulate_touch(model, [vertex], points=points, spacing=SPACING, angle=angle,
                                  rng=instance_rng(seed, m_index, instance))


def _touch(task):
    """One touch: recognise it, keeping every candidate's walk, for all deltas <= ``delta``."""
    models, m_index, instance, seed, length, angle, deltas, scans, options = task
    config = PaperConfig.from_options("paper", dict(options))
    db = scan_database(models, scans)
    entry = db.entries[m_index]
    vertex, touch = p3_touch(entry.model, m_index, instance, seed=seed, length=length, angle=angle)
    start = time.perf_counter()
    try:
        geom = config.geometry(touch) or estimate(touch)
    except InputError as exc:                  # counted as a failure, not the end of the run
        failed = {"recognized": None, "correct": False, "seconds": time.perf_counter() - start, "errors": {},
                  "candidates": {m: 0 for m in models}, "failed": str(exc)}
        return {"model": entry.name, "vertex": vertex, "length": length, "angle": angle, "estimate": None,
                "diagnosis": None, "results": {str(d): failed for d in deltas}}
    overhead = time.perf_counter() - start
    walks = {}
    for other in db.entries:
        table = other.table
        rows = table.candidates(geom.k1, geom.k2, max(deltas))
        t0 = time.perf_counter()
        problem = mesh_paper.MeshSuperposition(other.model, geom, touch.curves, phi_step=config.phi_step)
        found = problem.walks(table.samples.sites[rows, 0].astype(np.int64), max_steps=config.max_steps)
        dk = np.hypot(table.samples.k1[rows] - geom.k1, table.samples.k2[rows] - geom.k2)
        walks[other.name] = (dk, found, time.perf_counter() - t0, max(problem.evaluated, 1))
    # why a touch fails: is there a candidate near the truth, and does eq. 15 prefer the truth?
    true_problem = mesh_paper.MeshSuperposition(entry.model, geom, touch.curves, phi_step=config.phi_step)
    dk, found, _, _ = walks[entry.name]
    sites = entry.table.samples.sites[entry.table.candidates(geom.k1, geom.k2, max(deltas)), 0].astype(np.int64)
    here = entry.model.vertices[vertex]
    diagnosis = {
        "error_at_touch": true_problem.error(vertex)[0],
        "nearest_candidate_mm": float(np.min(np.linalg.norm(entry.model.vertices[sites] - here, axis=1)))
        if len(sites) else None,
        "walk_end_mm": float(np.linalg.norm(entry.model.vertices[min(found, key=lambda w: w[1])[0]] - here))
        if found else None,
    }
    results = {}
    for delta in deltas:
        errors = {}
        seconds = overhead
        for name, (dk, found, elapsed, evaluated) in walks.items():
            subset = [w for w, d in zip(found, dk) if d < delta]
            errors[name] = min((w[1] for w in subset), default=np.inf)
            # a smaller delta's walks are a subset: charged their share of the vertices evaluated
            needed = len(set().union(*(w[3] for w in subset))) if subset else 0
            seconds += elapsed * needed / evaluated
        best = min(errors, key=errors.get)
        best = best if np.isfinite(errors[best]) else None
        results[str(delta)] = {"recognized": best, "correct": best == entry.name, "seconds": seconds,
                               "errors": {n: (e if np.isfinite(e) else None) for n, e in errors.items()},
                               "candidates": {n: int(np.sum(w[0] < delta)) for n, w in walks.items()}}
    return {"model": entry.name, "vertex": vertex, "length": length, "angle": angle,
            "estimate": [geom.k1, geom.k2], "diagnosis": diagnosis, "results": results}


def _why_missed(record: dict, delta) -> str | None:
    """Why a touch was not recognised (None if it was):

    ``estimate_failed``: the curves gave no estimate;
    ``no_candidate``: no table row of the touched model within ``delta``;
    ``truth_fits_worse``: even at the touched vertex (best phi), eq. 15 is
    larger than the winning model's error; ``walk_missed``: the truth fits
    better, but no greedy walk on the touched model reached it.
    """
    result = record["results"][str(delta)]
    if result["correct"]:
        return None
    if result.get("failed"):
        return "estimate_failed"
    if result["candidates"][record["model"]] == 0:
        return "no_candidate"
    winner = result["errors"].get(result["recognized"]) if result["recognized"] else None
    if winner is not None and record["diagnosis"]["error_at_touch"] > winner:
        return "truth_fits_worse"
    return "walk_missed"


def _task_key(task) -> str:
    models, m_index, instance, seed, length, angle, deltas, scans, options = task
    return f"{models[m_index]}-{instance}-l{length:g}-phi{angle:g}"


def _code_hash() -> str:
    """Hash of the sources a record depends on."""
    return sources_hash(*CORE_SOURCES, "bench/paper_fig11.py")


def _touch_saved(job):
    """Run one task, or reuse its record from an interrupted run of the same code and settings."""
    task, folder = job
    models, _, _, seed, _, _, deltas, scans, options = task
    settings = {"models": list(models), "seed": seed, "deltas": list(deltas), "scans": scans, "options": dict(options)}
    saved = saved_record(folder / f"{_task_key(task)}.json", lambda: {"settings": settings, "record": _touch(task)},
                         accept=lambda s: s.get("settings") == settings)
    return saved["record"]


def run_fig11(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
              method: str = "paper", models: tuple[str, ...] | None = None, sweeps: dict | None = None,
              scans: str = "shipped", options: dict | None = None) -> dict:
    """P3 / Fig. 11: success rate and time per recognition along the three sweeps, on the scans as
    shipped or made like the paper's (``scans``, one of :data:`SCANS`), by the ``paper`` method with
    ``options`` (its readings; the output's name lists them)."""
    if scans not in SCANS:
        raise InputError(f"unknown scans {scans!r}; choose from {', '.join(SCANS)}")
    options, suffix = paper_options(options)
    out = Path(out)
    name = ("paper-fig11" if scans == "shipped" else f"paper-fig11-{scans}") + suffix
    models = tuple(models or BUILTIN_SETS["paper-fig11"])
    sweeps = sweeps or SWEEPS
    configs = {(DEFAULTS["length"], DEFAULTS["angle"]): sorted(set(sweeps["delta"]) | {DEFAULTS["delta"]})}
    for length in sweeps["length"]:
        configs.setdefault((length, DEFAULTS["angle"]), [DEFAULTS["delta"]])
    for angle in sweeps["angle"]:
        configs.setdefault((DEFAULTS["length"], angle), [DEFAULTS["delta"]])
    tasks = [(models, m, i, seed, length, angle, deltas, scans, options) for (length, angle), deltas in configs.items()
             for m in range(len(models)) for i in range(instances)]
    # each touch's record is saved as it completes, so an interrupted run resumes where it stopped
    parts = Path(out) / f"{name}.parts" / _code_hash()
    parts.mkdir(parents=True, exist_ok=True)
    records = run_parallel(_touch_saved, [(t, parts) for t in tasks], jobs=jobs or default_jobs(), quiet=quiet,
                           desc="paper-fig11")

    def summary(length, angle, delta):
        chosen = [r for r in records if r["length"] == length and r["angle"] == angle]
        rows = [r["results"][str(delta)] for r in chosen]
        misses = {}
        for r in chosen:
            why = _why_missed(r, delta)
            if why:
                misses[why] = misses.get(why, 0) + 1
        return {"success_percent": 100.0 * np.mean([r["correct"] for r in rows]),
                "median_seconds": float(np.median([r["seconds"] for r in rows])), "touches": len(rows),
                "misses": misses}

    table = {"benchmark": name, "scans": scans, "method": method, "options": dict(options), "instances": instances,
             "seed": seed, "models": list(models), "spacing_mm": SPACING, "defaults": DEFAULTS, "paper": PAPER,
             "delta": {str(d): summary(DEFAULTS["length"], DEFAULTS["angle"], d) for d in sweeps["delta"]},
             "length": {str(l): summary(l, DEFAULTS["angle"], DEFAULTS["delta"]) for l in sweeps["length"]},
             "angle": {str(a): summary(DEFAULTS["length"], a, DEFAULTS["delta"]) for a in sweeps["angle"]},
             "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{name}.json", table)
    table["plots"] = [str(_plot(table, out, name))]
    lines = [f"P3 / Fig. 11: {len(models)} YCB scans ({scans}), {instances} touches each per setting (seed {seed})"
             + "".join(f", {k} = {v:g}" for k, v in options)]
    for key, unit in (("delta", "1/mm"), ("length", "mm"), ("angle", "deg")):
        lines.append(f"  {key} ({unit}): " + ", ".join(
            f"{k}: {v['success_percent']:.0f}% {v['median_seconds']:.1f}s" for k, v in table[key].items()))
    at_defaults = table["delta"].get(str(DEFAULTS["delta"]))
    if at_defaults and at_defaults["misses"]:
        lines.append("  misses at the defaults: " + ", ".join(f"{k} {v}" for k, v in at_defaults["misses"].items()))
    lines.append("  paper: delta 0.005 -> 0.03: 37% -> 93% (4 s -> 115 s); l 9 -> 24 mm: 63% -> 93%; "
                 "phi 10 -> 60 deg: 69% -> 93%")
    table["text"] = "\n".join(lines)
    return table


def _plot(table, out: Path, name: str) -> Path:
    from ..plots import pyplot, save_figure

    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, (key, label) in zip(axes, (("delta", "delta (1/mm)"), ("length", "l (mm)"), ("angle", "phi (deg)"))):
        xs = [float(k) for k in table[key]]
        ys = [v["success_percent"] for v in table[key].values()]
        ax.plot(xs, ys, "o-", label="tactrec (paper method)")
        paper = table["paper"][key]
        ax.plot([float(k) for k in paper], [v["success"] for v in paper.values()], "s--", label="paper (end points)")
        for x, v in zip(xs, table[key].values()):
            ax.annotate(f"{v['median_seconds']:.0f}s", (x, v["success_percent"]), textcoords="offset points",
                        xytext=(0, 6), ha="center", fontsize=7)
        ax.set_xlabel(label)
        ax.set_ylabel("success rate (%)")
        ax.set_ylim(0, 105)
    axes[0].legend(fontsize=8, loc="lower right")
    path = out / f"{name}.png"
    save_figure(fig, path)
    return path
