"""The paper method's steps one at a time, on P3's touches (Fig. 11 at its defaults).

A recognition by the paper's mesh method can fail at three steps:

1. **Estimation and lookup** (Sections 3.1 and 3.2.1): the curvatures
   estimated from the curves must lie within ``delta`` of the table's
   (Section 5.2.2, paraboloid fits to the 30-70 nearest vertices) at a
   table row near the touch, or no walk starts there.  The paper fits "a
   parabola to a few data points on the curve and around p"; how few is
   not said, so the readings are the parabola over ``w`` points each side
   of ``p`` (:data:`WINDOWS`), this package's default (a cubic over the
   widest window the curve's own noise allows, :func:`tactrec.estimation.
   fit_curve`) and the plain parabola over that same window.
2. **The superposition error at the truth** (Section 5.3.1, eq. 15): at
   the touched vertex, with the best rotation ``phi``, the curves must fit
   better than anywhere else.  The paper scans ``phi`` for closed-form
   surfaces in steps refined by bisection (Section 4.2.1) and does not say
   how for meshes; the readings are a 10-degree scan (the ``paper``
   method's) and a 1-degree one, which stands for the refined scan.
3. **The greedy walk** (Section 5.3.2) from the candidates to the truth,
   which needs a recognition: ``tactrec bench paper-fig11``.

For every P3 touch (:func:`tactrec.bench.paper_fig11.p3_touch`, the same
touches as ``paper-fig11``), on the touched scan alone, this benchmark
measures steps 1 and 2 under each reading: the curvature gap to the
table's values at the touched vertex, whether a row within ``delta`` lies
within :data:`NEAR` mm of the touch, the data normal's tilt from the vertex
normal (eq. 13) and eq. 15 at the touched vertex.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..estimation import estimate
from ..io.atomic import write_text_atomic
from ..registration import mesh_paper
from ..surfaces import BUILTIN_SETS
from ..surfaces.mesh_table import vertex_curvatures
from .common import SCANS, run_parallel, scan_database, write_json
from .paper_fig11 import DEFAULTS, p3_touch

__all__ = ["run", "WINDOWS", "NEAR", "PHI_STEPS"]

#: the parabola's readings: points each side of ``p`` (None: the whole curve), and the default estimator
WINDOWS = (3, 5, 10, 20, None)
#: a table row this close to the touch (mm) puts a walk's start in the truth's neighbourhood
NEAR = 3.0
#: the rotation scans of eq. 15 (degrees)
PHI_STEPS = (10.0, 1.0)
#: eq. 15 at the truth above this (mm): the truth itself does not fit
NO_FIT = 1.0


def _readings() -> dict:
    out = {"default": {}, "parabola, window from the noise": {"window": "auto", "degree": 2}}
    for w in WINDOWS:
        out["parabola, all points" if w is None else f"parabola, {w} each side"] = {"window": w, "degree": 2}
    return out


def _touch(task) -> dict:
    models, m_index, instance, seed, scans = task
    entry = scan_database(models, scans).entries[m_index]
    model, table = entry.model, entry.table
    vertex, data = p3_touch(model, m_index, instance, seed=seed, length=DEFAULTS["length"],
                            angle=DEFAULTS["angle"])
    rotation = np.asarray(data.meta["truth"]["rotation"])          # data -> model
    k1_true, k2_true = (float(k[0]) for k in vertex_curvatures(model, [vertex]))
    here = model.vertices[vertex]
    record = {"model": entry.name, "instance": instance, "vertex": vertex, "table_at_touch": [k1_true, k2_true],
              "readings": {}}
    for name, options in _readings().items():
        try:
            geom = estimate(data, **options)
        except InputError as exc:
            record["readings"][name] = {"failed": str(exc)}
            continue
        rows = table.candidates(geom.k1, geom.k2, DEFAULTS["delta"])
        near = np.linalg.norm(table.samples.positions[rows] - here, axis=1) if len(rows) else np.array([np.inf])
        normal = rotation @ geom.normal
        tilt = np.degrees(np.arccos(np.clip(normal @ model.vertex_normals[vertex], -1.0, 1.0)))
        errors = {f"{step:g}": mesh_paper.MeshSuperposition(model, geom, data.curves, phi_step=step).error(vertex)[0]
                  for step in PHI_STEPS}
        record["readings"][name] = {"estimate": [geom.k1, geom.k2], "gap": float(np.hypot(geom.k1 - k1_true,
                                                                                           geom.k2 - k2_true)),
                                    "candidates": len(rows), "nearest_mm": float(near.min()),
                                    "tilt_deg": float(tilt), "error_at_touch": errors}
    return record


def _summary(records: list[dict], name: str) -> dict:
    rows = [r["readings"][name] for r in records]
    ok = [r for r in rows if "failed" not in r]
    if not ok:
        return {"touches": len(rows), "failed": len(rows)}
    gap = np.array([r["gap"] for r in ok])
    nearest = np.array([r["nearest_mm"] for r in ok])
    out = {"touches": len(rows), "failed": len(rows) - len(ok),
           "gap_median": float(np.median(gap)), "within_delta_percent": 100.0 * np.mean(gap < DEFAULTS["delta"]),
           "row_near_percent": 100.0 * np.mean(nearest <= NEAR),
           "tilt_median_deg": float(np.median([r["tilt_deg"] for r in ok])),
           "tilt_p90_deg": float(np.percentile([r["tilt_deg"] for r in ok], 90))}
    for step in PHI_STEPS:
        e = np.array([r["error_at_touch"][f"{step:g}"] for r in ok])
        out[f"error_at_touch_phi{step:g}"] = {"median": float(np.median(e)), "p90": float(np.percentile(e, 90)),
                                              "no_fit_percent": 100.0 * np.mean(e > NO_FIT)}
    return out


def run(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        models: tuple[str, ...] | None = None, scans: str = "paper-like", **_ignored) -> dict:
    """Steps 1 and 2 of the paper method under each reading on ``instances`` P3 touches per scan;
    writes ``paper-steps[-SCANS].json`` and ``.md``."""
    if scans not in SCANS:
        raise InputError(f"unknown scans {scans!r}; choose from {', '.join(SCANS)}")
    out = Path(out)
    name = "paper-steps" if scans == "shipped" else f"paper-steps-{scans}"
    models = tuple(models or BUILTIN_SETS["paper-fig11"])
    tasks = [(models, m, i, seed, scans) for m in range(len(models)) for i in range(instances)]
    records = run_parallel(_touch, tasks, jobs=jobs or 1, quiet=quiet, desc="paper-steps")
    table = {"benchmark": name, "scans": scans, "instances": instances, "seed": seed, "models": list(models),
             "defaults": DEFAULTS, "near_mm": NEAR, "no_fit_mm": NO_FIT,
             "readings": {r: _summary(records, r) for r in _readings()}, "records": records}
    write_json(out / f"{name}.json", table)
    table["text"] = _markdown(table)
    write_text_atomic(out / f"{name}.md", table["text"])
    return table


def _markdown(table: dict) -> str:
    d = table["defaults"]
    lines = [f"The paper method's steps on {len(table['records'])} P3 touches ({table['scans']} scans, seed "
             f"{table['seed']}; l = {d['length']:g} mm, phi = {d['angle']:g} deg, delta = {d['delta']:g} /mm), "
             "on the touched scan: the curvature gap to the table's fit at the touched vertex, the share within "
             f"delta, the share with a row within delta {table['near_mm']:g} mm from the touch, the data normal's "
             "tilt from the vertex normal, and eq. 15 at the touched vertex (median / p90, and the share above "
             f"{table['no_fit_mm']:g} mm) with phi scanned in 10- and 1-degree steps.", "",
             "| estimator | gap median (/mm) | within delta | row near | tilt median / p90 (deg) | eq. 15 at truth, "
             "10 deg | eq. 15 at truth, 1 deg |", "|---|---|---|---|---|---|---|"]
    for name, s in table["readings"].items():
        if "gap_median" not in s:
            lines.append(f"| {name} | failed on all {s['touches']} | | | | | |")
            continue
        e10, e1 = s["error_at_touch_phi10"], s["error_at_touch_phi1"]
        lines.append(f"| {name} | {s['gap_median']:.3f} | {s['within_delta_percent']:.0f}% | "
                     f"{s['row_near_percent']:.0f}% | {s['tilt_median_deg']:.1f} / {s['tilt_p90_deg']:.1f} | "
                     f"{e10['median']:.3f} / {e10['p90']:.3f} ({e10['no_fit_percent']:.0f}%) | "
                     f"{e1['median']:.3f} / {e1['p90']:.3f} ({e1['no_fit_percent']:.0f}%) |"
                     + (f" ({s['failed']} failed)" if s["failed"] else ""))
    return "\n".join(lines) + "\n"
