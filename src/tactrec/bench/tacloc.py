"""TacLoc's registration on the patches of ``bench patch`` (``tactrec bench tacloc``).

TacLoc (arXiv, 2026) registers a tactile patch onto an object's point cloud
without training: ISS keypoints, FPFH correspondences, a graph of consistent
pairs, cliques, and a verification of each candidate pose.  Its published code
is ``tacreg`` (MIT), run here as published: it is not on PyPI, so it is
installed from its repository (``pip install
git+https://github.com/zzhangje/tacreg``, or ``pip install DIR`` of a
checkout) beside ``make install-baselines`` (Open3D, scikit-learn, networkx,
joblib); without it this benchmark says so in one line.

TacLoc places a patch on one known object; to recognise, each patch is
registered onto every scan of the set (a cloud of the scan's vertices with
their normals, in metres, as TacLoc takes them) and the scans are ranked by
the same error as every method here: the mean exact distance of the patch's
points, under the pose found, to the scan.  Its parameters are its own
defaults (:data:`PARAMETERS` names what is set: the patch's normals estimated
by it, the scan's given; two parallel jobs, the cores here).  A pose it cannot
give (too few keypoints for its cliques: it raises) leaves that scan
unranked.  Reported per set and radius, beside ``fast`` on the same patches:
accuracy, the contact's error when right, seconds per patch over all scans,
and how many registrations it could not give.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import write_text_atomic
from ..registration.result import apply_poses
from .common import recognizer, run_parallel, saved_record, sources_hash, write_json
from .patch import DEFAULT_SETS, _db, _models, patch_touch

__all__ = ["run", "PARAMETERS", "RADII"]

#: the radii TacLoc is run at, mm (its keypoints need room: its defaults take ISS radii of 3-4 mm)
RADII = (6.0, 10.0)
#: what is set of TacLoc's parameters (the rest are its defaults)
PARAMETERS = {"estimate_src_normals": True, "estimate_tar_normals": False, "parallel_jobs": 2}


def _tacreg():
    try:
        import open3d  # noqa: F401
        from tacreg import TacRegParam, tacreg
    except ImportError as exc:
        raise InputError(f"TacLoc's code is not installed ({exc.name} is missing): run make install-baselines, "
                         "then pip install git+https://github.com/zzhangje/tacreg (it is not on PyPI)",
                         "tacloc") from None
    return tacreg, TacRegParam


def _cloud(points, normals=None):
    import open3d as o3d

    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64))
    if normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(normals, dtype=np.float64))
    return pcd


def _touch(task) -> dict:
    scans, m_index, instance, seed, radius = task
    tacreg, TacRegParam = _tacreg()
    db = _db(scans)
    entry = db.entries[m_index]
    _, touch = patch_touch(entry, m_index, instance, seed, radius)
    if touch is None:
        return {"scans": scans, "model": entry.name, "instance": instance, "radius": radius, "no_place": True}
    points = np.asarray(touch.patch.points, dtype=np.float64)
    errors, poses, failed = {}, {}, 0
    start = time.perf_counter()
    for e in db.entries:
        model = e.model
        try:
            R, t, _ = tacreg(_cloud(points * 1e-3), _cloud(model.vertices * 1e-3, model.vertex_normals),
                             TacRegParam(**PARAMETERS))
        except (ValueError, ZeroDivisionError, IndexError):
            failed += 1
            continue
        R, t = np.asarray(R, dtype=np.float64), np.asarray(t, dtype=np.float64).reshape(3) * 1e3
        errors[e.name] = float(np.mean(model.distance(apply_poses(R[None], t[None], points)[0])))
        poses[e.name] = (R, t)
    seconds = time.perf_counter() - start
    best = min(errors, key=errors.get) if errors else None
    contact = None
    if best == entry.name:
        R, t = poses[best]
        contact = float(np.linalg.norm(R @ touch.contact + t - np.asarray(touch.meta["truth"]["contact"])))
    fast = recognizer(db.entries).recognize(touch)
    return {"scans": scans, "model": entry.name, "instance": instance, "radius": radius, "recognized": best,
            "correct": best == entry.name, "contact_mm": contact, "seconds": seconds, "failed": failed,
            "errors": errors, "fast": fast.best, "fast_seconds": fast.seconds}


def _saved(job):
    task, folder = job
    return saved_record(folder / ("-".join(str(x) for x in task) + ".json"), lambda: _touch(task))


def run(*, out, instances: int = 2, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        sets=DEFAULT_SETS, radii=RADII, **_ignored) -> dict:
    """Register the patches of ``sets`` at ``radii`` with TacLoc; write ``tacloc.json`` and ``.md``."""
    _tacreg()
    out = Path(out)
    folder = out / "tacloc.parts" / sources_hash("bench/tacloc.py", "bench/patch.py", "simulation.py", "io")
    folder.mkdir(parents=True, exist_ok=True)
    tasks = [(scans, m, i, seed, float(r)) for scans in sets for r in radii for m in range(len(_models(scans)))
             for i in range(instances)]
    records = run_parallel(_saved, [(t, folder) for t in tasks], jobs=jobs or 1, quiet=quiet, desc="tacloc")
    lines = [f"TacLoc (tacreg, its defaults but {PARAMETERS}) and fast on the same patches, {instances} per scan "
             "and radius, seed {seed}.".replace("{seed}", str(seed)), "",
             "| set | radius mm | patches | TacLoc right | located (<= 1 mm) | registrations it could not give | "
             "s per patch (median) | fast right | fast s (median) |", "|---|---|---|---|---|---|---|---|---|"]
    summary = {}
    for scans in sets:
        for r in radii:
            rows = [x for x in records if x["scans"] == scans and x["radius"] == float(r) and not x.get("no_place")]
            if not rows:
                continue
            right = [x for x in rows if x["correct"]]
            s = {"patches": len(rows), "right": len(right),
                 "located": sum(x["contact_mm"] <= 1.0 for x in right),
                 "failed": sum(x["failed"] for x in rows), "registrations": len(rows) * len(_models(scans)),
                 "seconds": float(np.median([x["seconds"] for x in rows])),
                 "fast_right": sum(x["fast"] == x["model"] for x in rows),
                 "fast_seconds": float(np.median([x["fast_seconds"] for x in rows]))}
            summary[f"{scans}/{r:g}"] = s
            lines.append(f"| {scans} | {r:g} | {s['patches']} | {s['right']} | {s['located']} | "
                         f"{s['failed']} of {s['registrations']} | {s['seconds']:.1f} | {s['fast_right']} | "
                         f"{s['fast_seconds']:.2f} |")
    table = {"benchmark": "tacloc", "instances": instances, "seed": seed, "parameters": PARAMETERS,
             "summary": summary, "records": records, "text": "\n".join(lines) + "\n"}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "tacloc.json", table)
    write_text_atomic(out / "tacloc.md", table["text"])
    return table
