"""``tactrec demo``: the main job on the built-in model set, end to end.

Picks one of the built-in YCB scans (seeded), touches it as in the paper's
protocol P3 (three 24 mm curves, 60 degrees apart, points every 0.3 mm,
delivered in the sensor's frame), recognises the touch against every
built-in model (the closed-form surfaces and the ten YCB scans), prints the
ranking and writes a picture of the recognised model with the registered
curves, and beside it the same in an offline 3-D page (:mod:`tactrec.viewer`).
The model database is built once into the cache folder
(:func:`tactrec.database.cache_folder`) and reused.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .database import cached_database
from .recognition import Recognizer, default_workers
from .simulation import simulate_touch
from .surfaces import BUILTIN_SETS

__all__ = ["run_demo"]

LENGTH, ANGLE, SPACING = 24.0, 60.0, 0.3          # mm, degrees, mm: the paper's P3 defaults


def run_demo(*, seed: int = 0, out="tactrec-demo.png", quiet: bool = True) -> dict:
    """Run the demo; returns ``{"text", "result", "truth", "picture", "view"}`` (``view``: the HTML page
    beside the picture, :mod:`tactrec.viewer`)."""
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    db = cached_database(BUILTIN_SETS["builtin"], name="builtin", quiet=quiet)
    loaded = time.perf_counter() - start
    scans = [e for e in db.entries if e.model.kind == "mesh"]
    model = scans[int(rng.integers(len(scans)))].model
    vertex = int(rng.integers(len(model.vertices)))
    points = int(round(LENGTH / SPACING)) + 1
    touch = simulate_touch(model, [vertex], points=points, spacing=SPACING, angle=ANGLE, rng=rng)
    truth = touch.meta["truth"]
    with Recognizer(db, workers=default_workers()) as recognizer:
        result = recognizer.recognize(touch)
    lines = [f"models: {len(db)} built-in ({len(scans)} YCB scans, {len(db) - len(scans)} closed-form surfaces), "
             f"ready in {loaded:.1f} s",
             f"touched: {model.name} at vertex {vertex}, ({', '.join(f'{x:.1f}' for x in truth['contact'])}) mm; "
             f"3 curves x {points} points, {SPACING} mm apart, planes {ANGLE:g} degrees apart, sensor frame",
             f"estimated curvatures k1 = {result.estimate.k1:.4g} /mm, k2 = {result.estimate.k2:.4g} /mm",
             f"recognised: {result.best} in {result.seconds:.1f} s, confidence {result.confidence:.3f}, "
             f"unknown {result.unknown:.3f} "
             f"({'correct' if result.best == model.name else 'WRONG'}"
             f"{'; ambiguous: confidence below the threshold' if result.ambiguous else ''})", "ranking:"]
    for rank, r in enumerate(result.ranking, start=1):
        if r.ok:
            lines.append(f"  {rank:2d}. {r.model:20s} error {r.error:.4g} mm  probability "
                         f"{result.probabilities[r.model]:.3g}  ({r.candidates} candidates)")
        else:
            lines.append(f"   -. {r.model:20s} rejected: {r.rejected}")
    best = result.registration
    if best is not None and best.model == model.name:
        lines.append(f"contact found {np.linalg.norm(best.location - truth['contact']):.2f} mm from the truth")
    picture = view = None
    if out and best is not None:
        from .plots import plot_registration, save_figure

        shown = db.get(best.model).model
        curves = [best.scale * (c @ best.rotation.T) + best.translation for c in touch.curves]
        ax = plot_registration(shown, curves, location=best.location,
                               title=f"{best.model}: registered curves (error {best.error:.3g} mm)")
        save_figure(ax, out)
        picture = str(out)
        lines.append(f"wrote {out}")
        from .viewer import touch_scene, write_view

        page = Path(out).with_suffix(".html")
        write_view(page, touch_scene(result.to_json(), touch.curves, {e.name: e.model for e in db.entries},
                                     title=f"tactrec demo: a touch of {model.name}"))
        view = str(page)
        lines.append(f"wrote {page} (open it in a browser: the recognised model, the curves, the runners-up)")
    return {"text": "\n".join(lines), "result": result, "truth": truth, "picture": picture, "view": view}
