"""The paper's worked estimate (Section 4.3.1, METHOD section 2).

On the elliptic paraboloid ``z = x^2/1.5^2 + y^2/1.1^2`` at ``(u, v) =
(1.21, 0.43)``: three curves of 61 points, planes 60 degrees apart, with and
without uniform noise +/-0.001, over ``instances`` seeded touches; the
errors of the estimated normal and principal curvatures beside the paper's
single estimate (N = (0.1611, 0.5764, 0.8011), k1 = 0.9548, k2 = 0.6370
against the true N = (0.1612, 0.5827, 0.7966), k1 = 0.9074, k2 = 0.6519).
``options`` are the ``paper`` method's readings: with ``parabola_points``,
the paper's parabola over that many points each side of ``p``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..estimation import estimate
from ..methods.paper import PaperConfig
from ..simulation import simulate_touch
from ..surfaces import load_model
from .common import instance_rng, paper_options, readings_text, write_json

__all__ = ["run"]

UV = (1.21, 0.43)
SPACINGS = (0.005, 0.01, 0.02)
PAPER = {"normal": 0.0077, "k1": 0.0474, "k2": 0.0149}   # |estimate - truth| of the paper's example


def run(*, out, instances: int = 10, seed: int = 0, jobs=None, quiet: bool = False, method: str = "paper",
        options: dict | None = None) -> dict:
    out = Path(out)
    options, suffix = paper_options(options)
    config = PaperConfig.from_options("paper", dict(options))
    name = f"paper-example{suffix}"
    model = load_model("elliptic-paraboloid")
    k1, k2, n, _ = model.curvatures(np.array(UV[0]), np.array(UV[1]))
    rows = []
    for spacing in SPACINGS:
        for noise in (0.0, 0.001):
            errors = []
            for i in range(instances):
                touch = simulate_touch(model, UV, points=61, spacing=spacing, noise=noise,
                                       rng=instance_rng(seed, int(spacing * 1e4), int(noise * 1e4), i))
                geom = config.geometry(touch) or estimate(touch)
                R = np.array(touch.meta["truth"]["rotation"])
                errors.append([np.linalg.norm(R @ geom.normal - n), abs(geom.k1 - k1), abs(geom.k2 - k2)])
            e = np.array(errors)
            rows.append({"spacing": spacing, "noise": noise, "max": e.max(axis=0).tolist(),
                         "mean": e.mean(axis=0).tolist()})
    table = {"benchmark": name, "options": dict(options), "instances": instances, "seed": seed, "uv": UV,
             "truth": {"normal": n.tolist(), "k1": float(k1), "k2": float(k2)}, "paper_errors": PAPER, "rows": rows}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{name}.json", table)
    lines = [f"Section 4.3.1: estimates at (u, v) = {UV} on the elliptic paraboloid, 61 points per curve, "
             f"{instances} touches each (seed {seed}{readings_text(options)})",
             f"{'spacing':>8s} {'noise':>7s}   max |dN|  max |dk1|  max |dk2|   mean |dN| mean |dk1| mean |dk2|"]
    for r in rows:
        lines.append(f"{r['spacing']:8.3f} {r['noise']:7.3f}   " + " ".join(f"{x:9.5f}" for x in r["max"])
                     + "  " + " ".join(f"{x:9.5f}" for x in r["mean"]))
    lines.append(f"paper (one touch, noise 0.001): |dN| {PAPER['normal']}, |dk1| {PAPER['k1']}, |dk2| {PAPER['k2']}")
    table["text"] = "\n".join(lines)
    return table
