"""Protocol P4: lookup-table construction on meshes (paper Table 4).

For each of the ten YCB scans of the free-form reproduction (in millimetres):
vertices, triangles, bounding box, surface area, the number of sample
vertices chosen by the paper's sampling (Section 5.2.1) and the time it took,
and the time to fit the paraboloids of the table (Section 5.2.2), beside the
paper's Table 4 (whose models were other scans, 42k-101k vertices against
the YCB scans' ~8k).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..surfaces import BUILTIN_SETS, load_model
from ..surfaces.mesh_table import sample_vertices, vertex_curvatures
from .common import paper_values, write_json

__all__ = ["run_table4"]


def run_table4(*, out, instances: int = 1, seed: int = 0, jobs=None, quiet: bool = False,
               method: str = "paper", models: tuple[str, ...] | None = None) -> dict:
    """P4: ``instances`` repeats (different sampling seeds) per model (``models``, names of the
    ``paper-fig11`` scans; all ten by default); medians reported."""
    out = Path(out)
    rows = {}
    for name in models or BUILTIN_SETS["paper-fig11"]:
        model = load_model(name)
        samples, t_sample, t_table = [], [], []
        for i in range(instances):
            start = time.perf_counter()
            chosen = sample_vertices(model, rng=np.random.SeedSequence([seed, i]).generate_state(1)[0])
            t_sample.append(time.perf_counter() - start)
            start = time.perf_counter()
            vertex_curvatures(model, chosen)
            t_table.append(time.perf_counter() - start)
            samples.append(len(chosen))
        rows[name] = {"vertices": len(model.vertices), "triangles": len(model.faces),
                      "bounding_box_mm": np.ptp(model.vertices, axis=0).round(1).tolist(),
                      "surface_area_mm2": model.area, "sample_vertices": int(np.median(samples)),
                      "sampling_seconds": float(np.median(t_sample)), "table_seconds": float(np.median(t_table))}
    paper = paper_values()["table4"]
    table = {"benchmark": "paper-table4", "instances": instances, "seed": seed, "models": rows, "paper": paper}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "paper-table4.json", table)
    lines = ["P4 / Table 4: vertex sampling and lookup tables on the YCB scans (mm), beside the paper's models",
             f"{'model':16s} {'vertices':>8s} {'faces':>7s} {'samples':>7s} {'sample s':>8s} {'table s':>7s}   "
             f"{'paper model':12s} {'vertices':>8s} {'samples':>7s} {'sample s':>8s} {'table s':>7s}"]
    for (name, r), i in zip(rows.items(), range(len(paper["models"]))):
        lines.append(f"{name:16s} {r['vertices']:8d} {r['triangles']:7d} {r['sample_vertices']:7d} "
                     f"{r['sampling_seconds']:8.3f} {r['table_seconds']:7.3f}   {paper['models'][i]:12s} "
                     f"{paper['vertices'][i]:8d} {paper['sample_vertices'][i]:7d} {paper['sampling_seconds'][i]:8.3f} "
                     f"{paper['table_seconds'][i]:7.3f}")
    table["text"] = "\n".join(lines)
    return table
