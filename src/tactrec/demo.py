"""``tactrec demo``: the main job on the built-in model set, end to end.

Picks a built-in model (seeded), simulates a touch on it in the sensor's
frame, recognises it against every built-in model, prints the ranking and
writes a picture of the recognised model with the registered curves.
"""

from __future__ import annotations

import numpy as np

from .database import build_entries
from .recognition import recognize
from .simulation import simulate_random_touch
from .surfaces import BUILTIN_SETS

__all__ = ["run_demo"]


def run_demo(*, seed: int = 0, out="tactrec-demo.png", quiet: bool = True) -> dict:
    """Run the demo; returns ``{"text", "result", "truth", "picture"}``."""
    rng = np.random.default_rng(seed)
    db = build_entries(BUILTIN_SETS["builtin"], quiet=quiet)
    entry = db.entries[int(rng.integers(len(db)))]
    model = entry.model
    spacing = model.size / 150.0
    touch = simulate_random_touch(model, points=61, spacing=spacing, noise=spacing / 20.0, angle=60.0,
                                  margin=0.1, rng=rng)
    truth = touch.meta["truth"]
    result = recognize(touch, db)
    lines = [f"touched: {model.name} at ({', '.join(f'{x:.4g}' for x in truth['contact'])})"
             f" ({model.units or 'model units'}); 3 curves x 61 points, spacing {spacing:.3g}, noise +/-{spacing / 20:.2g}",
             f"estimated curvatures k1 = {result.estimate.k1:.4g}, k2 = {result.estimate.k2:.4g}",
             f"recognised: {result.best} in {result.seconds:.2f} s "
             f"({'correct' if result.best == model.name else 'WRONG'})", "ranking:"]
    for rank, r in enumerate(result.ranking, start=1):
        if r.ok:
            lines.append(f"  {rank}. {r.model:22s} error {r.error:.4g}  ({r.candidates} candidates)")
        else:
            lines.append(f"  -. {r.model:22s} rejected: {r.rejected}")
    best = result.registration
    if best is not None and best.model == model.name:
        error = model.location_error(best.location, truth["contact"])
        if error is not None:
            lines.append(f"location error (up to the surface's symmetries): {error:.3g}")
    picture = None
    if out and best is not None:
        from .plots import plot_registration, save_figure

        shown = db.get(best.model).model
        curves = [best.scale * (c @ best.rotation.T) + best.translation for c in touch.curves]
        ax = plot_registration(shown, curves, location=best.location,
                               title=f"{best.model}: registered curves (error {best.error:.3g})")
        save_figure(ax, out)
        picture = str(out)
        lines.append(f"wrote {out}")
    return {"text": "\n".join(lines), "result": result, "truth": truth, "picture": picture}
