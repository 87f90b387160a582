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
shown on its own), median / p95 / max seconds, the peak resident memory
of this process and of its largest worker during that size's run, and what
they hold of the machine together at its end (their proportional set sizes
summed: pages shared by fork counted once).  Each touch's record also holds
its search's work (closest-point queries), the deepest tier it reached,
whether it settled, and where the index ranked its true place
(:func:`place_rank`).

With ``--cluster local:1,local:2`` (any comma-separated cluster addresses,
:mod:`tactrec.cluster`) the same touches are first recognised on each
cluster, a ``local:N`` one started afresh for each size, this process its
client and holding the models without their distance fields (as
``--cluster`` commands do): the same columns, how many answers are those of
the one process to the byte (their JSON, timings aside), and the peak
resident memory of the client and of each worker.
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


def catalogue_folder(count: int = GENERATED, *, seed: int = 0, quiet: bool = True) -> Path:
    """The database of the first ``count`` generated meshes (seed ``seed``), built once into the cache
    folder (a stopped build resumes)."""
    from ..database import build_database, cache_folder
    from .catalogue import generate
    from .common import default_jobs

    paths = generate(cache_folder() / "catalogue", count=count, seed=seed, jobs=default_jobs(), quiet=quiet)
    folder = cache_folder() / f"catalogue-db-{paths[0].parent.name}-{count}"
    build_database(paths, folder, units="mm", quiet=quiet)
    return folder


def catalogue_entries(count: int = GENERATED, *, seed: int = 0, quiet: bool = True, fields: bool = True):
    """The first ``count`` generated meshes (seed ``seed``) with their tables (:func:`catalogue_folder`),
    loaded (``fields``: :func:`tactrec.database.load_database`'s)."""
    from ..database import load_database

    return load_database(catalogue_folder(count, seed=seed, quiet=quiet), fields=fields).entries


def _reset_peak() -> None:
    """Start this process's peak resident memory again from what it holds now (Linux's
    ``/proc/self/clear_refs``), so that each run's peak is its own (elsewhere it is the peak so far)."""
    try:
        with open("/proc/self/clear_refs", "w") as handle:
            handle.write("5")
    except OSError:
        pass


def _peak(pid: int | str = "self") -> float:
    """The peak resident memory (MB) of process ``pid`` (``VmHWM``), else of this one so far."""
    try:
        with open(f"/proc/{pid}/status") as handle:
            return next(int(line.split()[1]) for line in handle if line.startswith("VmHWM:")) / 1024.0
    except (OSError, StopIteration, ValueError):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _proportional(pids) -> float:
    """The proportional set sizes (MB) of processes ``pids`` summed (``Pss``: a page shared by n
    processes counts 1/n in each), what they hold of the machine's memory together; 0 where unread."""
    total = 0.0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/smaps_rollup") as handle:
                total += next(int(line.split()[1]) for line in handle if line.startswith("Pss:")) / 1024.0
        except (OSError, StopIteration, ValueError):
            return 0.0
    return total


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
    from .answers import digest, without_timings

    ok = [r.model for r in rec.ranking if r.ok]
    twin = rec.best not in (None, name) and family(name) is not None and family(rec.best) == family(name)
    return {"model": name, "recognized": rec.best, "rank": ok.index(name) + 1 if name in ok else None,
            "twin": bool(twin), "seconds": rec.seconds, "ambiguous": rec.ambiguous, "settled": rec.settled,
            "work": rec.work, "depth": rec.depth, "place_rank": place,
            "answer": digest(without_timings(rec.to_json()))}


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


def scan_picks(scans: int, instances: int, seed: int) -> list[int]:
    """The scans (indices among ``scans`` of them) this bench touches with ``instances`` touches a set and
    ``seed``: the draw :func:`_touches` makes."""
    return _picks(scans, 0, instances, seed)[0]


def _picks(scans: int, generated: int, instances: int, seed: int) -> tuple[list[int], list[int]]:
    rng = instance_rng(seed, 1_078)
    on_scans = [int(i) for i in rng.choice(scans, size=min(instances, scans), replace=False)]
    return on_scans, [scans + int(i) for i in rng.choice(generated, size=min(instances, generated), replace=False)]


def _touches(scans, generated, instances: int, seed: int) -> tuple[list[int], dict]:
    """The touched models (indices into the scans then the generated meshes) and their P3 touches, each
    ``(vertex, data)``."""
    on_scans, on_generated = _picks(len(scans), len(generated), instances, seed)
    entries = list(scans) + list(generated)
    return on_scans + on_generated, {k: vertex_touch(entries[k], k, 0, seed) for k in on_scans + on_generated}


def _size(recognizer, entries, size: int, touched: list[int], touches: dict, scans: int) -> dict:
    """One catalogue size's rows and summaries, ``recognizer`` recognising each touch (and its index
    ranking each touch's true place: :func:`place_rank`)."""
    from ..features import Touch
    from .catalogue import family_of

    chosen = [k for k in touched if k < size]
    rows = []
    for k in chosen:
        vertex, data = touches[k]
        found = recognizer.recognize(data)         # first: its seconds hold the index's pass over its places
        place = place_rank(recognizer.index, Touch.from_data(data), size, k, entries[k].model, vertex)
        rows.append(_outcome(found, entries[k].name, family_of, place))
    return {"all": _summary(rows), "scans": _summary([r for r, k in zip(rows, chosen) if k < scans]),
            "generated": _summary([r for r, k in zip(rows, chosen) if k >= scans]), "records": rows}


def _on_cluster(address: str, entries, size: int, touched, touches, scans: int) -> dict:
    """:func:`_size` on the cluster ``address`` (a new one per size for ``local:N``), this process its
    client, holding the models without their distance fields; the client's and each worker's peak
    resident memory."""
    from ..cluster import connect
    from ..recognition import Recognizer

    _reset_peak()
    with connect(address) as cluster:
        with Recognizer(entries[:size], cluster=cluster) as recognizer:
            out = _size(recognizer, entries, size, touched, touches, scans)
        workers = cluster.peak_mb()
    out["peak_mb"] = {"client": _peak(), "workers": list(workers.values())}
    return out


def run(*, out, instances: int = 20, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        cluster: str | None = None, **_ignored) -> dict:
    """The benchmark (module text); ``cluster``: comma-separated cluster addresses (``local:1,local:2``),
    each run too, before the one process (its client holding the models without their fields)."""
    from ..database import build_database, cache_folder, load_database
    from ..recognition import Recognizer, default_workers
    from .common import ycb_database

    out = Path(out)
    addresses = [a for a in (cluster or "").split(",") if a]
    table = {"benchmark": "scale-out", "seed": seed, "instances": instances, "sizes": {}, "clusters": {}}
    touched = None
    if addresses:
        build_database(("ycb",), cache_folder() / "ycb", quiet=quiet)
        scans = load_database(cache_folder() / "ycb", fields=False).entries
        generated = catalogue_entries(GENERATED, quiet=quiet, fields=False)
        touched, touches = _touches(scans, generated, instances, seed)
        for address in addresses:
            table["clusters"][address] = {str(size): _on_cluster(address, scans + generated, size, touched, touches,
                                                                 len(scans)) for size in SIZES}
        del scans, generated
    scans = ycb_database().entries
    generated = catalogue_entries(GENERATED, quiet=quiet)
    entries = list(scans) + list(generated)
    if touched is None:
        touched, touches = _touches(scans, generated, instances, seed)
    for size in SIZES:
        _reset_peak()
        with Recognizer(entries[:size], workers=default_workers()) as recognizer:
            row = _size(recognizer, entries, size, touched, touches, len(scans))
            pool = getattr(recognizer.runner, "pool", None)
            pids = pool.pids if pool is not None else []
            workers = [_peak(pid) for pid in pids]
            together = _proportional(["self", *pids])
        row["peak_mb"] = {"process": _peak(), "largest_worker": max(workers, default=0.0), "all_pss": together}
        table["sizes"][str(size)] = row
    for runs in table["clusters"].values():
        for size, row in runs.items():
            one = [r["answer"] for r in table["sizes"][size]["records"]]
            row["same_answers"] = int(sum(r["answer"] == a for r, a in zip(row["records"], one)))
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "scale-out.json", table)
    table["text"] = _text(table, seed, instances)
    (out / "scale-out.md").write_text(table["text"] + "\n", encoding="utf-8")
    return table


def _text(table: dict, seed: int, instances: int) -> str:
    lines = [f"P3 touches (seed {seed}): {instances} on YCB scans, {instances} on generated meshes, one process "
             "and its two workers per catalogue size", "",
             "| models | touches | top-1 | top-3 | near-twin confusions | median s | p95 s | max s | "
             "same scan touches: median s | true place's rank in the index: median / p90 / in the first round | "
             "peak MB (process / worker) | MB of all processes at the end (proportional) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for size, s in table["sizes"].items():
        a, y, m = s["all"], s["scans"], s["peak_mb"]
        lines.append(f"| {size} | {a['touches']} | {a['top1_percent']:.1f}% | {a['top3_percent']:.1f}% | "
                     f"{a['twin_confusions']} | {a['median_seconds']:.2f} | {a['p95_seconds']:.2f} | "
                     f"{a['max_seconds']:.2f} | {y['median_seconds']:.2f} | {a['place_rank_median']:.0f} / "
                     f"{a['place_rank_p90']:.0f} / {a['place_in_first_round_percent']:.0f}% | {m['process']:.0f} / "
                     f"{m['largest_worker']:.0f} | {m.get('all_pss', 0.0):.0f} |")
    for address, runs in table["clusters"].items():
        lines += ["", f"On the cluster {address} (this process its client, holding the models without their "
                      "distance fields):", "",
                  "| models | touches | top-1 | top-3 | median s | p95 s | max s | same answers as one process | "
                  "peak MB (client / each worker) |", "|---|---|---|---|---|---|---|---|---|"]
        for size, s in runs.items():
            a, m = s["all"], s["peak_mb"]
            lines.append(f"| {size} | {a['touches']} | {a['top1_percent']:.1f}% | {a['top3_percent']:.1f}% | "
                         f"{a['median_seconds']:.2f} | {a['p95_seconds']:.2f} | {a['max_seconds']:.2f} | "
                         f"{s['same_answers']} of {a['touches']} | {m['client']:.0f} / "
                         f"{' + '.join(f'{w:.0f}' for w in m['workers'])} |")
    return "\n".join(lines)
