"""What limits the ``fast`` search on scans (``tactrec bench search-limits``).

On the touches of ``fast-vs-paper`` (both protocols, the ten ``paper-fig11``
scans), two measurements that need the truth, and so no search:

``index``
    Where the true place ranks among the places in the order the search
    takes them (:func:`tactrec.registration.mesh_fast.places`: curvature gap,
    one place per grid cell): the rank of the first place within a cell's
    width (or one mean edge) of the true contact, the better of the normal's
    orientations; and which default tier first reaches it.
``basin``
    From the true pose turned about the true contact by ``angle`` degrees
    (about ``axes`` random axes, seeded), the share of refinements (the
    search's own: ``iterations`` exact steps on three times ``coarse_points``
    points a curve, then two on all points) that end within the fit limit
    (:func:`tactrec.probability.fit_limit`).  0 degrees is the ceiling: on
    noisy data the true pose itself may lie beyond the limit.  15 degrees is half the step
    of the all-rotations tiers; the estimated normal is off by a few
    degrees on coarse scans.

With each tier's estimated cost per model (closest-point queries), this says
how much of the search's time goes to places the index ranks low, and
whether the starts the tiers make can reach a fit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..features import Touch
from ..io.atomic import write_text_atomic
from ..methods import get_method
from ..methods.fast import TIERS, tier_cost, tier_places
from ..methods.fast_stages import tier_span
from ..probability import fit_limit
from ..registration import mesh_fast
from ..registration.solver import Criteria, solve
from ..surfaces import BUILTIN_SETS
from .common import PROTOCOLS, database, instance_rng, run_parallel, simulate, write_json

__all__ = ["run", "ANGLES"]

#: how far (degrees) the basin's starts are turned from the true pose
ANGLES = (0.0, 2.0, 8.0, 15.0)


def _tier_of(rank: int) -> str:
    """The first default tier whose places include ``rank`` (0-based)."""
    for k, tier in enumerate(TIERS):
        start, stop = tier_span(TIERS, k)
        if stop is None or rank < stop:
            return f"tier {k + 1}"
    return "beyond"


def _touch(task) -> dict:
    models, m_index, instance, seed, protocol, axes = task
    config = get_method("fast").configure()
    entry = database(models).entries[m_index]
    model = entry.model
    _, data = simulate(entry, m_index, instance, seed, protocol)
    truth = data.meta["truth"]
    touch = Touch.from_data(data)
    ranks = []
    for g in touch.orientations:
        chosen, _, _ = mesh_fast.places(model, g, touch.points, touch.radius, spread=config.spread)
        near = np.linalg.norm(model.vertices[chosen] - np.asarray(truth["contact"]), axis=1)
        hit = np.nonzero(near <= max(touch.radius / config.spread, model.mean_edge))[0]
        ranks.append(int(hit[0]) if len(hit) else len(chosen))
    R0, t0 = np.asarray(truth["rotation"]), np.asarray(truth["translation"])
    contact = touch.geometry.contact
    limit = fit_limit(touch, config.floor)
    rng = instance_rng(seed, m_index, instance, 7)
    axis = rng.normal(size=(axes, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    basin = {}
    for angle in ANGLES:
        R = np.einsum("hij,jk->hik", Rotation.from_rotvec(np.deg2rad(angle) * axis).as_matrix(), R0)
        t = (R0 @ contact + t0) - np.einsum("hij,j->hi", R, contact)
        R, t, _, _ = solve(model, R, t, touch.subset(3 * config.coarse_points),
                           Criteria(config.iterations, tolerance=config.tolerance))
        R, t, error, _ = solve(model, R, t, touch.points, Criteria(2, tolerance=config.tolerance))
        basin[f"{angle:g}"] = float(np.mean(error <= limit))
    return {"model": entry.name, "protocol": protocol, "instance": instance, "rank": min(ranks),
            "tier": _tier_of(min(ranks)), "basin": basin, "mean_edge": model.mean_edge, "radius": touch.radius}


def run(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        axes: int = 8, models: tuple[str, ...] | None = None, protocols: tuple[str, ...] = tuple(PROTOCOLS),
        **_ignored) -> dict:
    """Measure the index and the basin on ``instances`` touches per scan and protocol; write
    ``search-limits.json`` and ``.md``."""
    out = Path(out)
    models = tuple(models or BUILTIN_SETS["paper-fig11"])
    tasks = [(models, m, i, seed, p, axes) for p in protocols for m in range(len(models)) for i in range(instances)]
    records = run_parallel(_touch, tasks, jobs=jobs or 1, quiet=quiet, desc="search-limits")
    config = get_method("fast").configure()
    db = database(models)
    radius = PROTOCOLS["p3"]["length"] / 2.0                  # a P3 touch's, in the scans' millimetres
    cost = {e.name: [tier_cost(config, k, 1, tier_places(config, k, e.model, radius)) for k in range(len(TIERS))]
            for e in db.entries}
    summary = {}
    for protocol in protocols:
        rows = [r for r in records if r["protocol"] == protocol]
        ranks = np.array([r["rank"] for r in rows])
        summary[protocol] = {
            "touches": len(rows),
            "rank": {q: float(np.percentile(ranks, p, method="lower"))
                     for q, p in (("median", 50), ("p75", 75), ("p90", 90))},
            "tiers": {name: sum(r["tier"] == name for r in rows) for name in
                      [f"tier {k + 1}" for k in range(len(TIERS))] + ["beyond"]},
            "basin": {a: float(np.mean([r["basin"][a] for r in rows])) for a in rows[0]["basin"]},
            "basin_by_model": {m: {a: float(np.mean([r["basin"][a] for r in rows if r["model"] == m]))
                                   for a in rows[0]["basin"]} for m in models},
        }
    table = {"benchmark": "search-limits", "instances": instances, "seed": seed, "axes": axes,
             "models": list(models), "tiers": [repr(t) for t in TIERS], "tier_cost": cost,
             "mean_edge": {e.name: e.model.mean_edge for e in db.entries}, "summary": summary, "records": records}
    write_json(out / "search-limits.json", table)
    table["text"] = _markdown(table)
    write_text_atomic(out / "search-limits.md", table["text"])
    return table


def _markdown(table: dict) -> str:
    angles = [f"{a:g}" for a in ANGLES]
    lines = [f"The fast-vs-paper touches ({table['instances']} per scan and protocol, seed {table['seed']}).", "",
             "| protocol | true place's rank: median | p75 | p90 | first reached by tier 1 / 2 / 3 / 4 / beyond | "
             + " | ".join(f"fit from {a} deg" for a in angles) + " |",
             "|---" * (5 + len(angles)) + "|"]
    for protocol, s in table["summary"].items():
        r, tiers = s["rank"], " / ".join(str(v) for v in s["tiers"].values())
        lines.append(f"| {protocol} | {r['median']:g} | {r['p75']:g} | {r['p90']:g} | {tiers} | "
                     + " | ".join(f"{100 * s['basin'][a]:.0f}%" for a in angles) + " |")
    lines += ["", "| scan | mean edge (mm) | queries per tier 1 / 2 / 3 / 4 | "
              + " | ".join(f"{p} fit from {a} deg" for p in table["summary"] for a in angles) + " |",
              "|---" * (3 + len(angles) * len(table["summary"])) + "|"]
    for m in table["models"]:
        cells = [f"{100 * s['basin_by_model'][m][a]:.0f}%" for s in table["summary"].values() for a in angles]
        lines.append(f"| {m} | {table['mean_edge'][m]:.2f} | {' / '.join(f'{c:,}' for c in table['tier_cost'][m])} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
