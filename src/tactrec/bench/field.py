"""The distance fields against exact distances (``tactrec bench field``).

For every mesh of the set (the 78 YCB scans by default, ``--scans other``
for the meshes of :mod:`tactrec.bench.other_scans`, ``--scans cad`` for the
parts of :mod:`tactrec.bench.cad_parts`), the field is built as a
database builds it (:mod:`tactrec.surfaces.mesh_field`) and compared with
libigl's exact distances at ``instances`` x 1,000 seeded points: points on the
surface (uniform over its area: where a touch's points lie under the true
pose), and points within the band (along the face normals, up to the
truncation less two cells, where no corner of a cell is clipped).  Reported
per model and over all: spacing, bricks, bytes, build seconds, and the
absolute interpolation error's median, 95th percentile and maximum, in mm
and in cells.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .common import instance_rng, write_json

__all__ = ["run"]


def _points(model, rng, count: int, spread: float) -> np.ndarray:
    face = rng.choice(len(model.faces), size=count, p=_areas(model))
    b = rng.dirichlet(np.ones(3), count)
    p = np.einsum("ij,ijk->ik", b, model.vertices[model.faces[face]])
    return p + model.face_normals[face] * rng.uniform(-spread, spread, count)[:, None]


def _areas(model) -> np.ndarray:
    return model.face_areas / model.area


def _stats(error: np.ndarray, spacing: float) -> dict:
    q = np.percentile(error, [50, 95, 100])
    return {"median": float(q[0]), "p95": float(q[1]), "max": float(q[2]),
            "median_cells": float(q[0] / spacing), "p95_cells": float(q[1] / spacing)}


def _model(model, seed: int, index: int, count: int) -> dict:
    from ..surfaces.mesh_field import build_field

    start = time.perf_counter()
    field = build_field(model.vertices, model.faces, mean_edge=model.mean_edge)
    seconds = time.perf_counter() - start
    rng = instance_rng(seed, index)
    on = _points(model, rng, count, 0.0)
    band = _points(model, rng, count, field.truncation - 2 * field.spacing)
    exact = model.planes(band)[0]
    keep = np.abs(exact) < field.truncation - 2 * field.spacing
    return {"model": model.name, "vertices": len(model.vertices), "mean_edge": model.mean_edge,
            "spacing": field.spacing, "truncation": field.truncation, "bricks": len(field.bricks),
            "bytes": field.nbytes, "build_seconds": seconds,
            "on_surface": _stats(field.distance(on), field.spacing),
            "in_band": _stats(np.abs(field.signed(band[keep]) - exact[keep]), field.spacing)}


def run(*, out, instances: int = 5, seed: int = 0, jobs=None, quiet: bool = False, scans: str | None = None,
        **_ignored) -> dict:
    """Build every field of the set and measure it; write ``field.json`` and ``field.md``."""
    from tqdm import tqdm

    out = Path(out)
    if scans in ("other", "cad"):
        from .cad_parts import CAD
        from .other_scans import OTHER, other_database

        models = [e.model for e in other_database(OTHER if scans == "other" else CAD).entries]
    else:
        from ..surfaces import load_model, ycb_names

        models = [load_model(name) for name in ycb_names()]
    rows = [_model(m, seed, i, 1000 * instances)
            for i, m in enumerate(tqdm(models, desc="field", disable=quiet, leave=False))]
    total = {"models": len(rows), "bytes": int(sum(r["bytes"] for r in rows)),
             "build_seconds": float(sum(r["build_seconds"] for r in rows))}
    for key in ("on_surface", "in_band"):
        total[key] = {stat: float(np.median([r[key][stat] for r in rows])) for stat in ("median", "p95")}
        total[key]["max"] = float(max(r[key]["max"] for r in rows))
    suffix = f"-{scans}" if scans in ("other", "cad") else ""
    table = {"benchmark": f"field{suffix}", "scans": scans or "ycb", "instances": instances, "seed": seed,
             "total": total, "models": rows}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"field{suffix}.json", table)
    text = _markdown(table)
    (out / f"field{suffix}.md").write_text(text, encoding="utf-8")
    table["text"] = text
    return table


def _markdown(table: dict) -> str:
    t = table["total"]
    lines = [f"{t['models']} meshes ({table['scans']}), {1000 * table['instances']} points each on the surface and "
             f"in the band; fields {t['bytes'] / 1e6:.1f} MB in all, built in {t['build_seconds']:.1f} s",
             "",
             "| model | spacing mm | bricks | MB | build s | on the surface: median / p95 / max mm "
             "| in the band: median / p95 / max mm |",
             "|---|---|---|---|---|---|---|"]
    for r in table["models"]:
        s, b = r["on_surface"], r["in_band"]
        lines.append(f"| {r['model']} | {r['spacing']:.3f} | {r['bricks']} | {r['bytes'] / 1e6:.2f} | "
                     f"{r['build_seconds']:.2f} | {s['median']:.4f} / {s['p95']:.4f} / {s['max']:.3f} | "
                     f"{b['median']:.4f} / {b['p95']:.4f} / {b['max']:.3f} |")
    s, b = t["on_surface"], t["in_band"]
    lines.append(f"| **medians over the models** | | | | | {s['median']:.4f} / {s['p95']:.4f} / {s['max']:.3f} | "
                 f"{b['median']:.4f} / {b['p95']:.4f} / {b['max']:.3f} |")
    return "\n".join(lines) + "\n"
