"""What a user would pick instead of tactrec, on the same touches (``tactrec bench baselines``).

The touches are ``fast-vs-paper``'s (protocols ``p3`` and ``hard`` on the ten
YCB scans of Fig. 11); every method ranks the ten scans by the same error,
the exact mean distance of the registered data points to the scan, so only
the registration differs:

``fast``
    tactrec's default method.
``fpfh-ransac-icp``
    Open3D's global registration per scan: FPFH features on the data points
    and on the scan's vertices (normals from the mesh; the data's estimated
    from their neighbours, the touch's outward side used when known),
    RANSAC on feature matches, then point-to-plane ICP.
``multistart-icp``
    Open3D's point-to-plane ICP from the same starting poses as ``fast``
    (its ranked candidates, posed from the principal frames), the best kept.

Open3D is an optional extra: ``pip install 'tactrec[baselines]'`` (its wheel
loads ``libusb``, which the ``libusb-package`` wheel provides).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..estimation import estimate
from ..registration import mesh_fast
from .common import recognizer, run_parallel, write_json
from .common import PROTOCOLS, database, simulate

__all__ = ["run", "open3d", "METHODS"]

METHODS = ("fast", "fpfh-ransac-icp", "multistart-icp")


def open3d():
    """Import Open3D (preloading the ``libusb`` its wheel links against), or a one-line error."""
    try:
        import open3d as o3d
        return o3d
    except ImportError:
        pass
    try:
        import ctypes

        import libusb_package

        ctypes.CDLL(str(libusb_package.get_library_path()), mode=ctypes.RTLD_GLOBAL)
        import open3d as o3d
        return o3d
    except (ImportError, OSError, TypeError):
        raise InputError("needs Open3D: pip install 'tactrec[baselines]' (or make install-baselines)",
                         "baselines") from None


def _cloud(o3d, points, normals=None):
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    if normals is not None:
        pc.normals = o3d.utility.Vector3dVector(np.asarray(normals, dtype=np.float64))
    return pc


def _model_features(o3d, model, voxel):
    key = ("_o3d_features", voxel)
    hit = model.__dict__.get(key)
    if hit is None:
        pc = _cloud(o3d, model.vertices, model.vertex_normals)
        down = pc.voxel_down_sample(voxel)
        feat = o3d.pipelines.registration.compute_fpfh_feature(
            down, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100))
        hit = model.__dict__[key] = (pc, down, feat)
    return hit


def _fpfh_ransac_icp(o3d, model, touch, geom, *, seed: int):
    reg = o3d.pipelines.registration
    voxel = max(model.mean_edge, 1e-9)
    pc, down, feat = _model_features(o3d, model, voxel)
    data = _cloud(o3d, touch.points)
    data.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * voxel, max_nn=30))
    data.orient_normals_towards_camera_location(geom.contact + 100.0 * voxel * geom.normal)
    data_feat = reg.compute_fpfh_feature(data, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100))
    o3d.utility.random.seed(seed)
    ransac = reg.registration_ransac_based_on_feature_matching(
        data, down, data_feat, feat, False, 1.5 * voxel,
        reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel)],
        reg.RANSACConvergenceCriteria(100_000, 0.999))
    icp = reg.registration_icp(data, pc, 2 * voxel, ransac.transformation, reg.TransformationEstimationPointToPlane(),
                               reg.ICPConvergenceCriteria(max_iteration=50))
    return icp.transformation


def _multistart_icp(o3d, model, touch, geom, *, starts: int = 32):
    reg = o3d.pipelines.registration
    voxel = max(model.mean_edge, 1e-9)
    pc = _model_features(o3d, model, voxel)[0]
    data = _cloud(o3d, touch.points)
    R, t = mesh_fast.starting_poses(model, geom, touch.points, count=starts)
    best, best_fit = np.eye(4), -np.inf
    for Ri, ti in zip(R, t):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = Ri, ti
        icp = reg.registration_icp(data, pc, 2 * voxel, T, reg.TransformationEstimationPointToPlane(),
                                   reg.ICPConvergenceCriteria(max_iteration=30))
        score = icp.fitness - icp.inlier_rmse / voxel
        if score > best_fit:
            best, best_fit = icp.transformation, score
    return best


def _recognise_with(o3d, method, db, touch, *, seed):
    start = time.perf_counter()
    geom = estimate(touch)
    errors = {}
    for entry in db.entries:
        fn = _fpfh_ransac_icp if method == "fpfh-ransac-icp" else _multistart_icp
        options = {"seed": seed} if method == "fpfh-ransac-icp" else {}
        # without the outward side, both data normals are tried, as every method does
        best = np.inf
        for g in ([geom] if geom.oriented else [geom, geom.flipped()]):
            T = np.asarray(fn(o3d, entry.model, touch, g, **options))
            moved = touch.points @ T[:3, :3].T + T[:3, 3]
            best = min(best, float(np.mean(entry.model.distance(moved))))
        errors[entry.name] = best
    winner = min(errors, key=errors.get)
    return winner, time.perf_counter() - start


def _touch(task):
    models, m_index, instance, seed, protocol, methods = task
    o3d = open3d()
    db = database(models)
    entry = db.entries[m_index]
    site, touch = simulate(entry, m_index, instance, seed, protocol)
    results = {}
    for method in methods:
        if method == "fast":
            rec = recognizer(db.entries).recognize(touch)
            winner, seconds = rec.best, rec.seconds
        else:
            winner, seconds = _recognise_with(o3d, method, db, touch, seed=seed)
        results[method] = {"recognized": winner, "correct": winner == entry.name, "seconds": seconds}
    return {"model": entry.name, "protocol": protocol, "instance": instance, "site": site, "results": results}


def run(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        models: tuple[str, ...] | None = None, protocols=tuple(PROTOCOLS), methods=METHODS, **_ignored) -> dict:
    """Success rate and median time per recognition of each method; writes ``baselines.json``."""
    from ..surfaces import BUILTIN_SETS

    open3d()                                         # a missing extra is one line, before any work
    out = Path(out)
    models = tuple(models or BUILTIN_SETS["paper-fig11"])
    tasks = [(models, m, i, seed, p, tuple(methods)) for p in protocols for m in range(len(models))
             for i in range(instances)]
    records = run_parallel(_touch, tasks, jobs=jobs or 1, quiet=quiet, desc="baselines")
    summary = {p: {m: {"success_percent": 100.0 * float(np.mean([r["results"][m]["correct"] for r in records
                                                                  if r["protocol"] == p])),
                       "median_seconds": float(np.median([r["results"][m]["seconds"] for r in records
                                                          if r["protocol"] == p]))}
                   for m in methods} for p in protocols}
    table = {"benchmark": "baselines", "instances": instances, "seed": seed, "models": list(models),
             "summary": summary, "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "baselines.json", table)
    lines = [f"{len(models)} YCB scans, {instances} touches each per protocol (seed {seed}):",
             "| protocol | method | success | median s |", "|---|---|---|---|"]
    for p, by_method in summary.items():
        for m, s in by_method.items():
            lines.append(f"| {p} | {m} | {s['success_percent']:.0f}% | {s['median_seconds']:.3g} |")
    table["text"] = "\n".join(lines)
    return table
