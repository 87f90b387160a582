"""How far can a best-fit rule go on these touches? (``tactrec bench fit-limit``)

Recognition by registration (eq. 9) names the model the data fits best.  On
a small, noisy touch another scan may fit the data better than its own scan
does at the true pose: then no search, however thorough, recognises it by
that rule.  For the touches of ``fast-vs-paper`` (both protocols, same seeds)
this benchmark recognises each with ``fast`` and also refines the true pose
on the true scan (point-to-plane Gauss-Newton on all points, exact
distances).  Each miss is then one of

``outfitted``
    another scan fits better than every pose known on the true scan (the
    refined true pose and ``fast``'s own best there): the best-fit rule
    itself picks the other scan;
``search miss``
    the true scan has a pose fitting better than the winner, which the search
    did not find.

``ceiling_percent`` = 100 - outfitted: what a perfect search would reach by
the same rule, as far as the poses known tell (a better pose on the other
scans only lowers it).  Also reported: how many misses carry the
``ambiguous`` flag, and success among the results not flagged.

A miss is also tested against the noise: the winner's pose and the true pose
are compared point by point (a paired test on the data's distances to each
scan).  When the two mean distances differ by less than two standard errors
of that difference, the miss is *within the noise*: the data cannot tell the
two places apart, and which one fits better is down to the noise of this
touch.  ``clear_ceiling_percent`` = 100 - outfitted - search misses within
the noise: what a perfect search reaches where the data do tell them apart.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.atomic import write_text_atomic
from ..registration.result import apply_poses
from .common import CORE_SOURCES, recognizer, run_parallel, saved_record, sources_hash, write_json
from .common import PROTOCOLS, database, refined_truth, scan_set, simulate

__all__ = ["run"]


def _code_hash() -> str:
    return sources_hash(*CORE_SOURCES, "bench/fast_vs_paper.py", "bench/common.py", "bench/fit_limit.py")


def registered_distances(model, registration, x: np.ndarray) -> np.ndarray:
    """The distances of the data points ``x`` to ``model`` under ``registration`` (the data's units)."""
    return model.distance(apply_poses(registration.rotation[None] * registration.scale,
                                      registration.translation[None], x)[0]) / registration.scale


def paired_gap(winner: np.ndarray, truth: np.ndarray) -> float:
    """How many standard errors the data points lie farther from the winner than from the truth.

    ``winner (m,)`` and ``truth (m,)`` are each point's distance to the winning scan under its
    pose and to the true scan under the true pose.  Returns ``mean(d) / (std(d) / sqrt(m))``
    with ``d = winner - truth``: positive when the truth fits better, and below 2 in size when
    the difference is within the noise (0 when every point agrees, infinite when all differ
    alike).
    """
    d = np.asarray(winner, dtype=np.float64) - np.asarray(truth, dtype=np.float64)
    mean, se = float(np.mean(d)), float(np.std(d, ddof=1)) / np.sqrt(len(d))
    if se == 0.0:
        return 0.0 if mean == 0.0 else float(np.copysign(np.inf, mean))
    return mean / se


def _touch(task) -> dict:
    models, m_index, instance, seed, protocol = task
    db = database(models)
    entry = db.entries[m_index]
    site, touch = simulate(entry, m_index, instance, seed, protocol)
    rec = recognizer(db.entries).recognize(touch)
    errors = {r.model: r.error / r.scale for r in rec.ranking if r.ok}
    R, t, truth_error, scale = refined_truth(entry, touch)
    own = min(truth_error, errors.get(entry.name, np.inf))
    others = min((e for name, e in errors.items() if name != entry.name), default=np.inf)
    correct = rec.best == entry.name
    gap = None
    if not correct and rec.registration is not None:
        win = rec.registration
        x = np.asarray(touch.points, dtype=np.float64)
        on_winner = registered_distances(db.get(win.model).model, win, x)
        on_truth = entry.model.distance(apply_poses(R, t, x * scale)[0]) / scale
        gap = paired_gap(on_winner, on_truth)
    return {"model": entry.name, "protocol": protocol, "instance": instance, "site": site,
            "recognized": rec.best, "correct": correct, "ambiguous": rec.ambiguous, "seconds": rec.seconds,
            "truth_error": truth_error, "own_error": errors.get(entry.name),
            "best_other": others if np.isfinite(others) else None,
            "gap_se": gap, "within_noise": gap is not None and abs(gap) < 2.0,
            "kind": "correct" if correct else ("outfitted" if others < own else "search miss")}


def _touch_saved(job):
    task, folder = job
    models, m_index, instance, seed, protocol = task
    return saved_record(folder / f"{protocol}-{models[m_index]}-{instance}-s{seed}.json", lambda: _touch(task))


def _summary(rows: list[dict]) -> dict:
    n = len(rows)
    count = {k: sum(r["kind"] == k for r in rows) for k in ("correct", "outfitted", "search miss")}
    misses = [r for r in rows if not r["correct"]]
    sure = [r for r in rows if not r["ambiguous"]]
    return {"touches": n,
            "success_percent": 100.0 * count["correct"] / n,
            "outfitted_percent": 100.0 * count["outfitted"] / n,
            "search_miss_percent": 100.0 * count["search miss"] / n,
            "ceiling_percent": 100.0 - 100.0 * count["outfitted"] / n,
            "misses_flagged_ambiguous": sum(r["ambiguous"] for r in misses),
            "misses": len(misses),
            "misses_within_noise": sum(r["within_noise"] for r in misses),
            "clear_ceiling_percent": 100.0 - 100.0 * (count["outfitted"] + sum(
                r["within_noise"] for r in misses if r["kind"] == "search miss")) / n,
            "not_ambiguous": len(sure),
            "success_not_ambiguous_percent": 100.0 * np.mean([r["correct"] for r in sure]) if sure else None,
            "median_truth_error_mm": float(np.median([r["truth_error"] for r in rows]))}


def run(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        models: tuple[str, ...] | None = None, protocols=tuple(PROTOCOLS), scans: str | None = None,
        **_ignored) -> dict:
    """Classify ``fast``'s misses on the fast-vs-paper touches; write ``fit-limit.json`` and ``.md``
    (with ``scans="other"``, on the meshes of :mod:`tactrec.bench.other_scans`: ``fit-limit-other.*``)."""
    out = Path(out)
    models, name = scan_set(models, scans, "fit-limit")
    tasks = [(models, m, i, seed, p) for p in protocols for m in range(len(models)) for i in range(instances)]
    parts = out / "fit-limit.parts" / _code_hash()
    parts.mkdir(parents=True, exist_ok=True)
    records = run_parallel(_touch_saved, [(t, parts) for t in tasks], jobs=jobs or 1, quiet=quiet,
                           desc="fit-limit")
    table = {"benchmark": name, "scans": scans or "shipped", "instances": instances, "seed": seed, "models": list(models),
             "protocols": {p: PROTOCOLS[p] for p in protocols},
             "summary": {p: _summary([r for r in records if r["protocol"] == p]) for p in protocols},
             "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{name}.json", table)
    kind = "meshes from other sources" if scans == "other" else "YCB scans"
    lines = [f"{len(models)} {kind}, {instances} touches each per protocol (seed {seed}), method fast.", "",
             "| protocol | success | outfitted | search misses | ceiling | misses within the noise | "
             "ceiling beyond the noise | misses flagged ambiguous | success when not flagged |",
             "|---|---|---|---|---|---|---|---|---|"]
    for p, s in table["summary"].items():
        sure = "-" if s["success_not_ambiguous_percent"] is None else \
            f"{s['success_not_ambiguous_percent']:.0f}% of {s['not_ambiguous']}"
        lines.append(f"| {p} | {s['success_percent']:.0f}% | {s['outfitted_percent']:.0f}% | "
                     f"{s['search_miss_percent']:.0f}% | {s['ceiling_percent']:.0f}% | "
                     f"{s['misses_within_noise']} of {s['misses']} | {s['clear_ceiling_percent']:.0f}% | "
                     f"{s['misses_flagged_ambiguous']} of {s['misses']} | {sure} |")
    table["text"] = "\n".join(lines) + "\n"
    write_text_atomic(out / f"{name}.md", table["text"])
    return table
