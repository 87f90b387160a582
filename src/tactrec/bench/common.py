"""Shared machinery of the benchmarks: seeding, the sets and touches they share, worker processes, output.

The touches of ``fast-vs-paper`` (:data:`PROTOCOLS`, :func:`simulate`) and the P3 touch of the 78-scan
benches (:func:`vertex_touch`) are made here, with the databases they run on (:func:`database`,
:func:`ycb_database`), so that every bench and test that reuses them imports them from one place.
"""

from __future__ import annotations

import functools
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from importlib import resources
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..io.atomic import write_text_atomic

__all__ = ["spread", "paper_values", "instance_rng", "random_face_site", "random_site_touch", "run_parallel", "write_json", "default_jobs",
           "sources_hash", "saved_record", "recognizer", "CORE_SOURCES", "errors_on_every_model", "error_cell", "SCANS",
           "scan_database", "within_noise", "refined_truth", "PROTOCOLS", "SPACING", "database", "simulate", "scan_set", "ycb_database",
           "vertex_touch"]

#: a cache: the recognizers a benchmark process keeps, by models and options (their worker processes end with it)
_RECOGNIZER_CACHE: dict = {}
#: a cache: the databases a benchmark process keeps, prepared, by the models' names
_DATABASE_CACHE: dict = {}

#: the points' spacing of every bench touch, mm
SPACING = 0.3
#: the two protocols of ``fast-vs-paper`` and the benches that reuse its touches (:func:`simulate`)
PROTOCOLS = {
    "p3": {"length": 24.0, "angle": 60.0, "noise": 0.0, "outward": True, "site": "vertex"},
    "hard": {"length": 12.0, "angle": 30.0, "noise": 0.05, "outward": False, "site": "face"},
}


def recognizer(models, *, method: str = "fast", calibrated: bool = False, **options):
    """A :class:`~tactrec.recognition.Recognizer` for ``models`` (a list of entries) kept for the rest of
    this process: its models are prepared and its worker processes started once; ``calibrated``: with
    their null model of chance fits (:func:`null_model`)."""
    from ..recognition import Recognizer, default_workers

    key = (tuple(id(e) for e in models), method, calibrated, tuple(sorted(options.items())))
    if key not in _RECOGNIZER_CACHE:
        chance = null_model(models) if calibrated else None
        _RECOGNIZER_CACHE[key] = (Recognizer(models, method=method, workers=default_workers(), chance=chance,
                                             **options), list(models))
    return _RECOGNIZER_CACHE[key][0]


def database(models: tuple[str, ...]):
    """The built-in ``models`` (or those of :mod:`.other_scans` and :mod:`.cad_parts`) with their
    tables, each prepared for the search once (not charged to a recognition), kept for the rest of
    this process."""
    if models not in _DATABASE_CACHE:
        from ..database import build_entries
        from ..registration import mesh_fast
        from .cad_parts import CAD
        from .other_scans import OTHER, other_database

        db = other_database(models) if set(models) <= set(OTHER) | set(CAD) else build_entries(models)
        for entry in db.entries:
            mesh_fast.prepare(entry.model)
        _DATABASE_CACHE[models] = db
    return _DATABASE_CACHE[models]


def ycb_database():
    """All 78 YCB scans (built once into the cache folder), prepared, kept for the rest of this process."""
    if ("ycb",) not in _DATABASE_CACHE:
        from ..database import cached_database
        from ..registration import mesh_fast

        db = cached_database(("ycb",), name="ycb")
        for entry in db.entries:
            mesh_fast.prepare(entry.model)
        _DATABASE_CACHE[("ycb",)] = db
    return _DATABASE_CACHE[("ycb",)]


def simulate(entry, m_index: int, instance: int, seed: int, protocol: str, imperfections=None):
    """A touch of ``protocol`` (:data:`PROTOCOLS`) on ``entry`` (its site and the data), recorded by a
    sensor with ``imperfections`` (:class:`tactrec.sensor.Imperfections`; None: a perfect one)."""
    from ..simulation import simulate_touch, spread_vertices

    spec = PROTOCOLS[protocol]
    rng = instance_rng(seed, m_index, instance, 1 if protocol == "hard" else 0)
    points = int(round(spec["length"] / SPACING)) + 1
    options = dict(points=points, spacing=SPACING, angle=spec["angle"], noise=spec["noise"], noise_kind="gaussian",
                   outward=spec["outward"], imperfections=imperfections)
    model = entry.model
    if spec["site"] == "vertex":       # a vertex whose sections reach the curves' length: the instance's, or the next
        for k in range(instance, instance + 50):
            vertices = spread_vertices(model, k + 1, rings=15, rng=instance_rng(seed, m_index))
            if k >= len(vertices) and k > instance:
                break
            site = [int(vertices[min(k, len(vertices) - 1)])]
            try:
                return site, simulate_touch(model, site, rng=rng, **options)
            except ValueError:
                continue
        raise RuntimeError(f"no vertex of {model.name} takes a {spec['length']} mm touch")
    for _ in range(50):                           # a face whose sections reach the curves' length
        site = random_face_site(model, rng)
        try:
            return site, simulate_touch(model, site, rng=rng, **options)
        except ValueError:
            continue
    raise RuntimeError(f"no face of {model.name} takes a {spec['length']} mm touch")


def vertex_touch(entry, m_index: int, instance: int, seed: int):
    """The P3 touch of the 78-scan benches on ``entry``: a vertex (no two instances within 15 rings),
    three 24 mm curves 60 degrees apart (81 points), in a sensor frame: ``(vertex, data)``."""
    from ..simulation import simulate_touch, spread_vertices

    vertices = spread_vertices(entry.model, instance + 1, rings=15, rng=instance_rng(seed, m_index))
    vertex = int(vertices[min(instance, len(vertices) - 1)])
    touch = simulate_touch(entry.model, [vertex], points=81, spacing=SPACING, angle=60.0,
                           rng=instance_rng(seed, m_index, instance))
    return vertex, touch


def scan_set(models, scans: str | None, bench: str) -> tuple[tuple[str, ...], str]:
    """The models a bench on the fast-vs-paper touches runs on (the ten YCB scans of Fig. 11 unless
    given; with ``scans="other"`` the meshes of :mod:`tactrec.bench.other_scans`, with ``"cad"`` the
    machined parts of :mod:`tactrec.bench.cad_parts`) and the name of its output files."""
    from ..errors import InputError
    from ..surfaces import BUILTIN_SETS

    if scans in ("other", "cad"):
        from .cad_parts import CAD
        from .other_scans import OTHER

        return tuple(models or (OTHER if scans == "other" else CAD)), f"{bench}-{scans}"
    if scans not in (None, "shipped"):
        raise InputError(f"{bench} runs on the shipped scans or on 'other' or 'cad' ones, not {scans!r}", "--scans")
    return tuple(models or BUILTIN_SETS["paper-fig11"]), bench


#: the kinds of scan a benchmark runs on: as shipped, or made like the paper's
#: (:func:`tactrec.surfaces.paper_like.paper_like`: 60-95 mm across, at least 42,000 vertices)
SCANS = ("shipped", "paper-like")


@functools.lru_cache(maxsize=2)
def scan_database(models: tuple[str, ...], scans: str = "shipped"):
    """The built-in ``models`` with their tables, as shipped or (meshes) made like the paper's
    (``scans``, one of :data:`SCANS`), kept for the rest of this process."""
    from ..database import Database, model_entry, build_entries
    from ..errors import InputError
    from ..surfaces import load_model

    if scans == "shipped":
        return build_entries(models)
    if scans == "paper-like":
        from ..surfaces.paper_like import paper_like

        return Database([model_entry(paper_like(load_model(m))) for m in models])
    raise InputError(f"unknown scans {scans!r}; choose from {', '.join(SCANS)}")


def paper_options(options: dict | None, method: str = "paper") -> tuple[tuple, str]:
    """The ``paper`` method's reading options (:class:`tactrec.methods.paper.PaperConfig`), validated before
    any work, as a sorted tuple, and the suffix they add to a benchmark's output name."""
    from ..errors import InputError
    from ..methods.paper import PaperConfig

    items = tuple(sorted((k, v) for k, v in (options or {}).items() if v is not None))
    if items and method != "paper":
        raise InputError("--paper-option applies to the paper method only", method)
    PaperConfig.from_options("paper", dict(items))
    return items, "".join(f"-{k.replace('_', '-')}{v:g}" for k, v in items)


def readings_text(options: tuple) -> str:
    """The ``paper`` method's reading options (:func:`paper_options`) as printed after a table's settings."""
    return "".join(f"; {k} = {v:g}" for k, v in options)


def paper_values() -> dict:
    """The paper's published numbers (``paper_values.json``)."""
    return json.loads((resources.files("tactrec.bench") / "paper_values.json").read_text(encoding="utf-8"))


def instance_rng(seed: int, *keys: int) -> np.random.Generator:
    """A generator for one instance, independent of how instances are split over workers."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), *map(int, keys)]))


def random_face_site(model, rng) -> list:
    """A site uniform over a random face of mesh ``model``: ``[face, b1, b2]`` (barycentric)."""
    face = int(rng.integers(len(model.faces)))
    b = rng.dirichlet(np.ones(3))
    return [face, float(b[1]), float(b[2])]


def random_site_touch(model, rng, spec: dict, *, vertex: bool = False, imperfections=None):
    """A touch of mesh ``model`` (:func:`tactrec.simulation.simulate_touch` with the options ``spec``)
    at a random vertex (``vertex``) or :func:`random_face_site`, drawn again until one takes it (at most
    100 draws)."""
    from ..simulation import simulate_touch

    for _ in range(100):
        site = [int(rng.integers(len(model.vertices)))] if vertex else random_face_site(model, rng)
        try:
            return simulate_touch(model, site, imperfections=imperfections, rng=rng, **spec)
        except ValueError:
            continue
    raise RuntimeError(f"no place of {model.name} takes the touch")


def default_jobs() -> int:
    return max(1, min(2, os.cpu_count() or 1))


def run_parallel(fn: Callable, tasks: Sequence, *, jobs: int, quiet: bool, desc: str) -> list:
    """``[fn(t) for t in tasks]``, in order, over ``jobs`` processes, with a progress bar."""
    from tqdm import tqdm

    bar = tqdm(total=len(tasks), desc=desc, file=sys.stderr, disable=quiet or not sys.stderr.isatty(), leave=False)
    results = []
    try:
        if jobs <= 1:
            for t in tasks:
                results.append(fn(t))
                bar.update()
        else:
            with ProcessPoolExecutor(max_workers=jobs) as pool:
                for r in pool.map(fn, tasks, chunksize=1):
                    results.append(r)
                    bar.update()
    finally:
        bar.close()
    return results


def spread(values) -> dict:
    """``{"median", "p95", "max"}`` of ``values`` (each None where there are none)."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return {"median": None, "p95": None, "max": None}
    return {"median": float(np.median(v)), "p95": float(np.percentile(v, 95)), "max": float(v.max())}


def write_json(path: Path, table: dict) -> None:
    write_text_atomic(path, json.dumps(table, indent=1, default=_default) + "\n")


def _default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(type(obj).__name__)


#: the sources every recognition depends on (files, or folders of ``.py`` files, relative to the package)
CORE_SOURCES = ("io", "estimation.py", "estimation_patch.py", "features.py", "linalg.py", "simulation.py", "tables.py", "recognition",
                "runner.py", "tip.py", "outliers.py", "probability.py", "bootstrap.py", "chance", "surfaces", "registration",
                "methods", "engine", "index", "compiled.py", "missed.py", "normal_scales.py", "units.py", "errors.py")


def null_model(entries, kinds=("curves",)):
    """The null model of chance fits of the models ``entries`` (:mod:`tactrec.chance`): fitted once, with
    ``ceil(160 / models)`` touches a model (at least 4, at most 32) of each of ``kinds`` from seed 0, and
    kept in the cache folder under the models' key, the kinds and the sources' hash."""
    import math

    from ..chance import catalogue_key, load, save
    from ..chance.fit import calibrate
    from ..database import cache_folder
    from ..recognition import Recognizer, default_workers

    key = catalogue_key(entries)
    label = "" if tuple(kinds) == ("curves",) else "-" + "-".join(kinds)
    folder = cache_folder() / "chance" / f"{key[:20]}-{sources_hash(*CORE_SOURCES)}{label}"
    found = load(folder, key)
    if found is None:
        with Recognizer(entries, workers=default_workers()) as r:
            found = calibrate(r, touches=max(4, min(32, math.ceil(160 / len(entries)))), seed=0, kinds=kinds)
        folder.mkdir(parents=True, exist_ok=True)
        save(found, folder)
        found = load(folder, key)                  # as stored (rounded), whether fitted now or before
    return found


def sources_hash(*relative: str) -> str:
    """Hash of the package sources a saved record depends on (files, or folders of ``.py`` files,
    relative to the package): a changed method invalidates the records of an interrupted run."""
    import hashlib

    root = Path(str(resources.files("tactrec")))
    h = hashlib.sha256()
    for rel in relative:
        path = root / rel
        for file in sorted(path.glob("*.py")) if path.is_dir() else [path]:
            h.update(file.read_bytes())
    return h.hexdigest()[:16]


def saved_record(path: Path, compute: Callable[[], dict], *, accept: Callable[[dict], bool] = lambda saved: True
                 ) -> dict:
    """The record saved at ``path`` if there is one and ``accept`` takes it, else ``compute()``,
    written there atomically (so an interrupted benchmark resumes where it stopped)."""
    if path.exists():
        try:
            saved = json.loads(path.read_text(encoding="utf-8"))
            if accept(saved):
                return saved
        except (ValueError, KeyError, TypeError):
            pass
    record = compute()
    write_json(path, record)
    return record


def refined_truth(entry, touch) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The true pose of a simulated ``touch`` (its ``meta["truth"]``) refined on ``entry``'s model,
    point-to-plane, 30 exact steps on all its points: ``R (1, 3, 3)`` and ``t (1, 3)`` (data onto
    model, model units), the refined fit's mean distance in the data's units, and the data-to-model
    ``scale``."""
    from ..registration.solver import Criteria, solve
    from ..units import conversion

    truth = touch.meta["truth"]
    scale = conversion(touch.units, getattr(entry.model, "units", None))
    R = np.asarray(truth["rotation"], dtype=np.float64)[None]
    t = np.asarray(truth["translation"], dtype=np.float64)[None] * scale
    R, t, refined, _ = solve(entry.model, R, t, touch.points * scale, Criteria(30))
    return R, t, float(refined[0]) / scale, scale


def errors_on_every_model(data, entries, *, method: str, **options) -> dict:
    """One recognition of ``data`` against ``entries``, in this process: the model recognised, the
    wall time and every model's registration error in the data's units (None where the model was
    rejected or left unregistered)."""
    import time

    from ..recognition import recognize

    start = time.perf_counter()
    result = recognize(data, entries, method=method, **options)
    return {"recognized": result.best, "seconds": time.perf_counter() - start,
            "errors": {r.model: (r.error / r.scale if r.ok else None) for r in result.ranking}}


def error_cell(value, missing: str = "NC") -> str:
    """A registration error in a printed table (``missing`` where there is none)."""
    return missing if value is None else f"{value:.3f}"


def within_noise(a: float, b: float, *, points: int, fit: float) -> bool:
    """Whether two fits' mean distances ``a`` and ``b`` (eq. 8) to the same ``points`` data points are
    within the noise: at most two standard errors apart, the standard error of a fit of mean
    distance ``fit`` under the data's own noise.  Under Gaussian noise the distances of a right fit
    are half-normal, whose spread is ``sqrt(pi / 2 - 1)`` times their mean, so another draw of the
    same noise moves ``fit`` by about ``fit sqrt(pi / 2 - 1) / sqrt(points)``."""
    from ..probability import fit_standard_error

    return abs(a - b) <= 2.0 * fit_standard_error(fit, points)
