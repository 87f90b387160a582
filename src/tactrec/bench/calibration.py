"""Does the confidence mean what it says? (``tactrec bench calibration``)

Single touches recognised by ``fast``, each result's confidence (the best
model's probability, :mod:`tactrec.probability`) set against whether it was
right:

``hard``
    ``fast-vs-paper``'s hard touches on the ten ``paper-fig11`` scans
    (contact anywhere on a face, 12 mm curves 30 degrees apart, Gaussian noise
    of 0.05 mm, no outward side, random sensor frame): ``instances`` per scan.
``p3-78``
    The paper's P3 touches (contact at a vertex, 24 mm curves 60 degrees
    apart, points every 0.3 mm) on all 78 YCB scans, recognised against all
    78 (``tactrec bench scale``'s touches): ``ceil(instances / 25)`` per scan.

For each set: the expected calibration error (ECE: over ten equal-width bins
of confidence, the touch-weighted mean gap between the bin's accuracy and
its mean confidence), the accuracy among results with confidence >= 0.95,
and a reliability diagram (``calibration.png``).  A finite set of touches
shows some ECE even for perfect probabilities; ``ece_if_calibrated`` is that
floor: the median ECE of 200 seeded draws of right and wrong answers from
the confidences themselves.  Each record keeps the
evidence the probabilities come from (:class:`tactrec.probability.Evidence`)
and the true pose's own fit (refined on the true scan); the probabilities are
computed from the evidence when the table is made, so a change of the
probability model is measured on the saved touches without recognising them
again.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..io.atomic import write_text_atomic
from ..probability import Evidence, residuals
from ..surfaces import BUILTIN_SETS
from .common import (CORE_SOURCES, database, recognizer, refined_truth, run_parallel, saved_record, simulate,
                     sources_hash, vertex_touch, write_json, ycb_database)

__all__ = ["run", "SETS", "expected_calibration_error", "reliability"]

SETS = ("hard", "p3-78")
#: the targets: ECE at most this, and among results this sure, at least this share right
ECE_TARGET, SURE, SURE_RIGHT = 0.05, 0.95, 0.95


def _code_hash() -> str:
    return sources_hash(*CORE_SOURCES, "bench/fast_vs_paper.py", "bench/common.py", "bench/scale.py")


def expected_calibration_error(confidence, correct, *, bins: int = 10) -> float:
    """ECE over ``bins`` equal-width bins of ``confidence (n,)`` against ``correct (n,)`` (bool)."""
    return float(sum(b["count"] * abs(b["accuracy"] - b["confidence"]) for b in reliability(confidence, correct,
                                                                                              bins=bins))
                 / max(len(confidence), 1))


def reliability(confidence, correct, *, bins: int = 10) -> list[dict]:
    """Per non-empty bin of confidence: its range, touches, mean confidence and accuracy."""
    c = np.asarray(confidence, dtype=np.float64)
    ok = np.asarray(correct, dtype=bool)
    which = np.minimum((c * bins).astype(int), bins - 1)
    out = []
    for b in range(bins):
        sel = which == b
        if sel.any():
            out.append({"low": b / bins, "high": (b + 1) / bins, "count": int(sel.sum()),
                        "confidence": float(c[sel].mean()), "accuracy": float(ok[sel].mean())})
    return out


def _truth_fit(entry, touch) -> dict:
    """The true pose refined on the true scan: its evidence against the recognition's."""
    R, t, _, scale = refined_truth(entry, touch)
    r = residuals(entry.model, R[0], t[0], touch.points, scale)
    return {"squares": float(np.sum(r * r))}


def _record(entry, touch, rec, extra: dict) -> dict:
    """A touch's record: the recognition's evidence (the probabilities are computed from it when the
    table is made, so a change of :mod:`tactrec.probability` re-scores saved touches)."""
    return dict(extra, model=entry.name, recognized=rec.best, correct=rec.best == entry.name, settled=rec.settled,
                depth=rec.depth, seconds=rec.seconds, evidence=rec.evidence.to_json(),
                errors={r.model: r.error / r.scale for r in rec.ranking if r.ok},
                truth=_truth_fit(entry, touch))


def scored(record: dict) -> dict:
    """``record`` with the probabilities of the current model: ``confidence`` (the recognised model's)
    and ``truth_probability`` (the touched model's)."""
    p, _ = Evidence.from_json(record["evidence"]).named_outcomes()
    return dict(record, confidence=p.get(record["recognized"], 0.0), truth_probability=p.get(record["model"], 0.0))


def _hard(task) -> dict:

    models, m_index, instance, seed = task
    db = database(models)
    entry = db.entries[m_index]
    site, touch = simulate(entry, m_index, instance, seed, "hard")
    return _record(entry, touch, recognizer(db.entries).recognize(touch), {"set": "hard", "instance": instance,
                                                                           "site": site})


def _p3_78(task) -> dict:
    m_index, instance, seed = task
    db = ycb_database()
    entry = db.entries[m_index]
    vertex, touch = vertex_touch(entry, m_index, instance, seed)
    return _record(entry, touch, recognizer(db.entries).recognize(touch), {"set": "p3-78", "instance": instance,
                                                                           "site": [vertex]})


def _saved(job):
    kind, task, folder = job
    fn = _hard if kind == "hard" else _p3_78
    name = "-".join(str(x) for x in task[1:]) if kind == "hard" else "-".join(str(x) for x in task)
    return saved_record(folder / f"{kind}-{name}.json", lambda: fn(task))


def ece_if_calibrated(confidence, *, draws: int = 200, seed: int = 0) -> float:
    """The median ECE of answers drawn right with probability ``confidence (n,)``: what a perfectly
    calibrated predictor shows on this many touches with these confidences."""
    c = np.asarray(confidence, dtype=np.float64)
    rng = np.random.default_rng(seed)
    return float(np.median([expected_calibration_error(c, rng.random(len(c)) < c) for _ in range(draws)]))


def summary(rows: list[dict]) -> dict:
    """ECE, reliability and the sure results' accuracy of ``rows`` (records with ``confidence``
    and ``correct``)."""
    conf = [r["confidence"] for r in rows]
    ok = [r["correct"] for r in rows]
    sure = [r for r in rows if r["confidence"] >= SURE]
    seconds = [r["seconds"] for r in rows]
    return {"touches": len(rows), "accuracy_percent": 100.0 * float(np.mean(ok)) if rows else None,
            "ece": expected_calibration_error(conf, ok), "ece_if_calibrated": ece_if_calibrated(conf),
            "mean_confidence": float(np.mean(conf)) if rows else None,
            "sure": len(sure), "sure_accuracy_percent": 100.0 * float(np.mean([r["correct"] for r in sure]))
            if sure else None,
            "median_seconds": float(np.median(seconds)) if rows else None,
            "reliability": reliability(conf, ok)}


def _plot(table: dict, path: Path) -> None:
    from ..plots import pyplot, save_figure

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5, 5))
    ax.plot([0, 1], [0, 1], color="grey", lw=0.8, ls="--", label="calibrated")
    for name, s in table["summary"].items():
        bins = s["reliability"]
        ax.plot([b["confidence"] for b in bins], [b["accuracy"] for b in bins], marker="o",
                label=f"{name} (ECE {s['ece']:.3f}, {s['touches']} touches)")
    ax.set_xlabel("confidence")
    ax.set_ylabel("accuracy")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("reliability of single-touch confidence (fast)")
    save_figure(fig, path)


def run(*, out, instances: int = 10, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        sets=SETS, **_ignored) -> dict:
    """Recognise the touches of ``sets``; write ``calibration.json``, ``.md`` and ``.png``."""
    from ..surfaces import ycb_names

    out = Path(out)
    folder = out / "calibration.parts" / _code_hash()
    folder.mkdir(parents=True, exist_ok=True)
    jobs_list = []
    if "hard" in sets:
        models = tuple(BUILTIN_SETS["paper-fig11"])
        jobs_list += [("hard", (models, m, i, seed), folder) for m in range(len(models)) for i in range(instances)]
    if "p3-78" in sets:
        per = math.ceil(instances / 25)
        jobs_list += [("p3-78", (m, i, seed), folder) for m in range(len(ycb_names())) for i in range(per)]
    records = [scored(r) for r in run_parallel(_saved, jobs_list, jobs=jobs or 1, quiet=quiet, desc="calibration")]
    table = {"benchmark": "calibration", "instances": instances, "seed": seed,
             "targets": {"ece": ECE_TARGET, "sure": SURE, "sure_right": SURE_RIGHT},
             "summary": {s: summary([r for r in records if r["set"] == s]) for s in sets},
             "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "calibration.json", table)
    lines = [f"Single touches recognised by fast (seed {seed}); confidence = the best model's probability.", "",
             "| set | touches | accuracy | mean confidence | ECE | ECE if calibrated | confidence >= 0.95 | "
             "right among them | median s |", "|---|---|---|---|---|---|---|---|---|"]
    for name, s in table["summary"].items():
        sure = "-" if s["sure_accuracy_percent"] is None else f"{s['sure_accuracy_percent']:.1f}%"
        lines.append(f"| {name} | {s['touches']} | {s['accuracy_percent']:.1f}% | {s['mean_confidence']:.3f} | "
                     f"{s['ece']:.3f} | {s['ece_if_calibrated']:.3f} | {s['sure']} | {sure} | "
                f"{s['median_seconds']:.2f} |")
    table["text"] = "\n".join(lines) + "\n"
    write_text_atomic(out / "calibration.md", table["text"])
    _plot(table, out / "calibration.png")
    return table
