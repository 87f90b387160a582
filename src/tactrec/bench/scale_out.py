"""A catalogue of 1,078 models: the 78 YCB scans and 1,000 generated meshes (``tactrec bench scale-out``).

The generated meshes are :mod:`tactrec.bench.catalogue`'s (seed 0), in
families of four near twins; their database is built once into the cache
folder (resumable) and kept.  The catalogue grows in :data:`SIZES`: the 78
scans, then the first generated families, then all of them.

Touches: P3 (a vertex, three 24 mm curves 60 degrees apart, points every
0.3 mm, sensor frame, :func:`tactrec.bench.common.vertex_touch`).
``instances`` touches on seeded scans of the 78, recognised against every
size (the same touches: how time grows with the catalogue), and as many on
seeded generated meshes, recognised against each size that holds their
mesh.  Each size runs in its own :class:`~tactrec.recognition.Recognizer`
(one process and its two workers), closed before the next.

Reported per size: top-1 and top-3 over the touches, how many wrong answers
name a near twin of the touched mesh (its own family: counted wrong, and
shown on its own), median / p95 / max seconds, and the peak resident memory
of this process and of its largest worker.
"""

from __future__ import annotations

import resource
from pathlib import Path

import numpy as np

from ..methods.fast_config import FastConfig
from .common import instance_rng, vertex_touch, write_json

__all__ = ["run", "SIZES", "GENERATED", "catalogue_entries", "place_rank"]

#: catalogue sizes: the 78 scans, with the first 172 generated meshes, with all 1,000
SIZES = (78, 250, 1078)
#: generated meshes in the largest catalogue
GENERATED = 1000


def catalogue_entries(count: int = GENERATED, *, seed: int = 0, quiet: bool = True):
    """The first ``count`` generated meshes (seed ``seed``) with their tables, built once into the
    cache folder (a stopped build resumes) and loaded."""
    from ..database import build_database, cache_folder, load_database
    from .catalogue import generate
    from .common import default_jobs

    paths = generate(cache_folder() / "catalogue", count=count, seed=seed, jobs=default_jobs(), quiet=quiet)
    folder = cache_folder() / f"catalogue-db-{paths[0].parent.name}-{count}"
    build_database(paths, folder, units="mm", quiet=quiet)
    return load_database(folder).entries


def _peak_mb() -> tuple[float, float]:
    """Peak resident memory (MB) of this process and of its largest child that has ended."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    return own, children


def place_rank(index, touch, size: int, k: int, model, vertex: int) -> int | None:
    """Where the index of places (:class:`~tactrec.index.PlaceIndex`) ranks the true place of a touch
    of model ``k`` at ``vertex`` among the places of the first ``size`` models: the first of model
    ``k``'s places within a cell and a half of the vertex whose normal lies within 37 degrees of its
    (1 = first); None where no such place is ranked."""
    from ..surfaces.mesh_rings import CELL_MM
    from ..units import conversion

    ranked = index.ranked(touch, range(size), len(index))
    rows = np.flatnonzero(ranked.model == k)
    place = ranked.vertex[rows]
    near = np.linalg.norm(model.vertices[place] - model.vertices[vertex], axis=1) <= \
        1.5 * CELL_MM * conversion("mm", model.units)
    normal = model.fine_curvatures.normal
    facing = np.sum(normal[place] * normal[vertex], axis=1) > 0.8
    hits = rows[near & facing]
    return int(hits[0]) + 1 if len(hits) else None


def _outcome(rec, name: str, family, place: int | None) -> dict:
    ok = [r.model for r in rec.ranking if r.ok]
    twin = rec.best not in (None, name) and family(name) is not None and family(rec.best) == family(name)
    return {"model": name, "recognized": rec.best, "rank": ok.index(name) + 1 if name in ok else None,
            "twin": bool(twin), "seconds": rec.seconds, "ambiguous": rec.ambiguous, "settled": rec.settled,
            "place_rank": place}


def _summary(rows: list[dict]) -> dict:
    if not rows:
        return {}
    ranks = [r["rank"] for r in rows]
    seconds = [r["seconds"] for r in rows]
    places = np.array([np.inf if r["place_rank"] is None else r["place_rank"] for r in rows])
    return {"touches": len(rows), "top1_percent": 100.0 * np.mean([k == 1 for k in ranks]),
            "top3_percent": 100.0 * np.mean([k is not None and k <= 3 for k in ranks]),
            "twin_confusions": int(sum(r["twin"] for r in rows)),
            "ambiguous": int(sum(r["ambiguous"] for r in rows)),
            "unsettled": int(sum(not r["settled"] for r in rows)),
            "median_seconds": float(np.median(seconds)), "p95_seconds": float(np.percentile(seconds, 95)),
            "max_seconds": float(np.max(seconds)),
            "place_rank_median": float(np.median(places)), "place_rank_p90": float(np.percentile(places, 90)),
            "place_in_first_round_percent": 100.0 * float(np.mean(places <= FastConfig.index_round))}


def run(*, out, instances: int = 20, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        **_ignored) -> dict:
    from ..features import Touch
    from ..recognition import Recognizer, default_workers
    from .catalogue import family_of
    from .common import ycb_database

    out = Path(out)
    scans = ycb_database().entries
    generated = catalogue_entries(GENERATED, quiet=quiet)
    entries = list(scans) + list(generated)
    rng = instance_rng(seed, 1_078)
    on_scans = [int(i) for i in rng.choice(len(scans), size=min(instances, len(scans)), replace=False)]
    on_generated = [len(scans) + int(i) for i in rng.choice(len(generated), size=min(instances, len(generated)),
                                                             replace=False)]
    touches = {k: vertex_touch(entries[k], k, 0, seed) for k in on_scans + on_generated}
    table = {"benchmark": "scale-out", "seed": seed, "instances": instances, "sizes": {}}
    for size in SIZES:
        chosen = [k for k in on_scans + on_generated if k < size]
        with Recognizer(entries[:size], workers=default_workers()) as recognizer:
            rows = []
            for k in chosen:
                vertex, data = touches[k]
                place = place_rank(recognizer.index, Touch.from_data(data), size, k, entries[k].model, vertex)
                rows.append(_outcome(recognizer.recognize(data), entries[k].name, family_of, place))
        own, worker = _peak_mb()
        table["sizes"][str(size)] = {
            "all": _summary(rows), "scans": _summary([r for r, k in zip(rows, chosen) if k < len(scans)]),
            "generated": _summary([r for r, k in zip(rows, chosen) if k >= len(scans)]),
            "peak_mb": {"process": own, "largest_worker": worker}, "records": rows}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "scale-out.json", table)
    lines = [f"P3 touches (seed {seed}): {instances} on YCB scans, {instances} on generated meshes, one process "
             "and its two workers per catalogue size", "",
             "| models | touches | top-1 | top-3 | near-twin confusions | median s | p95 s | max s | "
             "same scan touches: median s | true place's rank in the index: median / p90 / in the first round | "
             "peak MB (process / worker) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for size, s in table["sizes"].items():
        a, y, m = s["all"], s["scans"], s["peak_mb"]
        lines.append(f"| {size} | {a['touches']} | {a['top1_percent']:.1f}% | {a['top3_percent']:.1f}% | "
                     f"{a['twin_confusions']} | {a['median_seconds']:.2f} | {a['p95_seconds']:.2f} | "
                     f"{a['max_seconds']:.2f} | {y['median_seconds']:.2f} | {a['place_rank_median']:.0f} / "
                     f"{a['place_rank_p90']:.0f} / {a['place_in_first_round_percent']:.0f}% | {m['process']:.0f} / "
                     f"{m['largest_worker']:.0f} |")
    table["text"] = "\n".join(lines)
    (out / "scale-out.md").write_text(table["text"] + "\n", encoding="utf-8")
    return table
