"""What ``tactrec bench multi-touch`` reports from its saved sessions (:mod:`tactrec.bench.multi_touch`).

Kept apart from the sessions' code: the saved sessions are keyed by a hash of
the sources they run, and a change to what is reported from them reruns
none.  Each step of a saved session holds its answer, confidence, seconds
(the add's, the touch's own search's, per stage of the add) and, for the
true pose, the numbers :func:`truth_found` needs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..session import STAGES, allowed_fit
from .calibration import expected_calibration_error
from .common import spread

__all__ = ["summary", "text", "plot", "truth_found", "paired", "SURE"]

#: a session is sure of its answer at this confidence
SURE = 0.95


def truth_found(truth: dict | None) -> bool:
    """Whether a session's pose of the true model fits the touches kept as well as the true pose:
    its points-weighted mean distance ``truth["found"]`` (None: no pose of the true model) within
    the session's own allowance (:func:`tactrec.session.allowed_fit` over the touches' ``points``)
    of the true pose's ``fit``, or of the touches' ``limit`` (the points-weighted mean of their
    :func:`~tactrec.probability.fit_limit`) where that is larger: on noise-free touches the true
    pose fits to rounding, and a fit within the touches' noise is as good as it."""
    if not truth or truth.get("found") is None:
        return False
    return bool(truth["found"] <= allowed_fit(max(truth["fit"], truth["limit"]), truth["points"]))


def _at(steps: list, k: int) -> dict:
    """The session's state after ``k`` touches (its last, if it stopped before)."""
    return steps[min(k, len(steps)) - 1]


def _over_own(step: dict) -> float | None:
    """An add's time over the added touch's own recognition (None where that was not timed)."""
    return step["seconds"] / step["own_seconds"] if step.get("own_seconds") else None


def _stages(adds: list[dict]) -> dict:
    """Where the adds' time goes, per stage of :data:`tactrec.session.STAGES`: how many adds ran it,
    its share of all the adds' seconds, and its seconds over the added touch's own search (median
    over the adds that ran it)."""
    adds = [a for a in adds if a.get("stages") and a.get("own_seconds")]
    total = sum(a["seconds"] for a in adds)
    out = {}
    for stage in STAGES:
        ran = [a for a in adds if a["stages"].get(stage, 0.0) > 0.0]
        out[stage] = {"adds": len(ran), "share": sum(a["stages"][stage] for a in ran) / total if total else None,
                      "over_own_median": float(np.median([a["stages"][stage] / a["own_seconds"] for a in ran]))
                      if ran else None}
    return out


def summary(rows: list[dict], strategies, touches: int) -> dict:
    """Per strategy of ``strategies`` (each row has every one), the figures of
    :mod:`tactrec.bench.multi_touch`'s text, after 1 to ``touches`` touches."""
    out = {}
    first = [r[strategy][0]["seconds"] for r in rows for strategy in strategies]
    for strategy in strategies:
        per_k = []
        for k in range(1, touches + 1):
            states = [_at(r[strategy], k) for r in rows]
            conf = [s["confidence"] for s in states]
            ok = [s["correct"] for s in states]
            found = [truth_found(s["truth"]) for s in states if "truth" in s]
            per_k.append({"touches": k, "accuracy_percent": 100.0 * float(np.mean(ok)),
                          "mean_confidence": float(np.mean(conf)), "ece": expected_calibration_error(conf, ok),
                          "truth_found_percent": 100.0 * float(np.mean(found)) if found else None})
        decide = [_to_sure(r[strategy], touches) for r in rows]
        right = [_to_right(r[strategy], touches) for r in rows]
        # sure and wrong: a session whose answer at some touch count is wrong at confidence >= 0.95
        sure_wrong = sum(any(not s["correct"] and s["confidence"] >= SURE for s in r[strategy]) for r in rows)
        adds = [s["seconds"] for r in rows for s in r[strategy][1:] if not s.get("missed")]    # a missed line searches nothing
        # an add to a session of n touches, against the added touch's own recognition: a session that
        # stops early leaves its easy adds out of the pooled median, so the medians per n are reported too
        by_n, own = [], []
        for n in range(1, touches):
            ratios = [_over_own(r[strategy][n]) for r in rows if len(r[strategy]) > n]
            ratios = [x for x in ratios if x is not None]
            by_n.append({"touches_before": n, "adds": len(ratios), **spread(ratios)})
            own += ratios
        out[strategy] = {"per_touches": per_k, "mean_touches_to_right": float(np.mean(right)),
                         "mean_touches_to_0.99": float(np.mean(decide)),
                         "sure_wrong_sessions": int(sure_wrong),
                         "add_seconds": spread(adds),
                         "add_ratio_of_medians": float(np.median(adds) / np.median(first)) if adds else None,
                         "add_over_own": spread(own), "add_over_own_by_touches": by_n,
                         "propose_seconds": spread([s["propose_seconds"] for r in rows for s in r[strategy]
                                                        if "propose_seconds" in s]),
                         "add_stages": _stages([s for r in rows for s in r[strategy][1:]])}
    out["first_touch_seconds"] = spread(first)
    out["sessions"] = len(rows)
    if "next" in strategies and "random" in strategies:
        out["next_against_random"] = paired(rows, touches)
    return out


def _to_sure(steps: list, touches: int) -> int:
    """The touches a session took to reach confidence 0.99 (``touches`` if it never did)."""
    return next((i + 1 for i, s in enumerate(steps) if s["confidence"] >= 0.99), touches)


def _to_right(steps: list, touches: int) -> int:
    """The touches a session took until its answer was right at confidence >= :data:`SURE` and stayed
    right through every later touch (``touches`` if it never did): a session sure of the right
    answer early that a later touch turns wrong has not decided then."""
    return next((i + 1 for i, s in enumerate(steps)
                 if s["correct"] and s["confidence"] >= SURE and all(t["correct"] for t in steps[i:])), touches)


def paired(rows: list[dict], touches: int) -> dict:
    """``next`` against random places on the same sessions (same first touch): the extra touches
    each needs beyond the first until its answer is right at confidence >= :data:`SURE` and stays
    right (:func:`_to_right`; ``touches`` - 1 where it never does), their means, how much fewer
    ``next`` needs (percent of random's), the sessions each is earlier in, and the Wilcoxon
    signed-rank test's two-sided p-value of the paired differences (zeros dropped, the normal
    approximation with its correction for ties: the differences are small integers; None when every
    difference is 0); and the same for reaching confidence 0.99 (``"at_0.99"``)."""
    out = _paired(rows, touches, _to_right)
    if out:
        out["at_0.99"] = _paired(rows, touches, _to_sure)
    return out


def _paired(rows: list[dict], touches: int, reached) -> dict:
    """:func:`paired`'s figures for one measure of when a session has decided, ``reached(steps, touches)``."""
    from scipy.stats import wilcoxon

    extra = np.array([[reached(r[s], touches) - 1 for s in ("next", "random")] for r in rows], dtype=np.float64)
    if not len(extra):
        return {}
    d = extra[:, 0] - extra[:, 1]
    p = float(wilcoxon(d, zero_method="wilcox", method="approx").pvalue) if np.any(d != 0) else None
    mean_next, mean_random = float(extra[:, 0].mean()), float(extra[:, 1].mean())
    return {"extra_next": mean_next, "extra_random": mean_random,
            "fewer_percent": 100.0 * (1.0 - mean_next / mean_random) if mean_random > 0 else None,
            "next_earlier": int(np.sum(d < 0)), "random_earlier": int(np.sum(d > 0)), "p_value": p}


def plot(table: dict, out: Path) -> None:
    from ..plots import pyplot, save_figure

    plt = pyplot()
    touches = table["touches"]
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, s in table["summary"].items():
        for strategy in table["strategies"]:
            k = [p["touches"] for p in s[strategy]["per_touches"]]
            acc = [p["accuracy_percent"] for p in s[strategy]["per_touches"]]
            ax.plot(k, acc, marker="o", ls="-" if strategy == "next" else "--", label=f"{name}, {strategy}")
    ax.axhline(99, color="grey", lw=0.8)
    ax.set_xlabel("touches")
    ax.set_ylabel("accuracy (%)")
    ax.set_xticks(range(1, touches + 1))
    ax.legend(fontsize=8)
    ax.set_title("multi-touch sessions: accuracy against touches")
    save_figure(fig, out / "multi-touch.png")
    from .calibration import reliability

    fig, ax = plt.subplots(figsize=(5, 5))
    ax.plot([0, 1], [0, 1], color="grey", lw=0.8, ls="--")
    for r in table["records_by_set"]:
        rows = table["records_by_set"][r]
        conf = [s["confidence"] for row in rows for strategy in table["strategies"] for s in row[strategy]]
        ok = [s["correct"] for row in rows for strategy in table["strategies"] for s in row[strategy]]
        bins = reliability(conf, ok)
        ax.plot([b["confidence"] for b in bins], [b["accuracy"] for b in bins], marker="o",
                label=f"{r} (ECE {expected_calibration_error(conf, ok):.3f})")
    ax.set_xlabel("confidence")
    ax.set_ylabel("accuracy")
    ax.legend(fontsize=8)
    ax.set_title("reliability over every session state")
    save_figure(fig, out / "multi-touch-reliability.png")


def text(table: dict) -> str:
    """The run's tables (markdown): accuracy and confidence per touch count, the add's cost, where it
    goes, and how often the true pose is found."""
    seed, touches = table["seed"], table["touches"]
    lines = [f"Sessions of up to {touches} touches (seed {seed}), method fast; accuracy (mean confidence) after "
             "each touch count.", "",
             "| set | strategy | " + " | ".join(f"{k} touch{'es' if k > 1 else ''}" for k in range(1, touches + 1))
             + " | touches to right at 0.95, staying right | touches to 0.99 | sure (>= 0.95) and wrong "
             "| add s median / p95 / max | add / first, medians | add / the touch alone, median / p95 / max |",
             "|---|---|" + "---|" * (touches + 6)]
    for name, s in table["summary"].items():
        for strategy in table["strategies"]:
            st = s[strategy]
            cells = [f"{p['accuracy_percent']:.1f}% ({p['mean_confidence']:.2f})" for p in st["per_touches"]]
            a = st["add_seconds"]
            adds = "-" if a["median"] is None else f"{a['median']:.2f} / {a['p95']:.2f} / {a['max']:.2f}"
            ratio = "-" if st["add_ratio_of_medians"] is None else f"{st['add_ratio_of_medians']:.2f}"
            o = st["add_over_own"]
            own = "-" if o["median"] is None else f"{o['median']:.2f} / {o['p95']:.2f} / {o['max']:.2f}"
            lines.append(f"| {name} ({s['sessions']}) | {strategy} | " + " | ".join(cells)
                         + f" | {st.get('mean_touches_to_right', float('nan')):.2f} | {st['mean_touches_to_0.99']:.2f} | "
                         f"{st.get('sure_wrong_sessions', '-')} | {adds} | "
                         f"{ratio} | {own} |")
    pairs = {name: s["next_against_random"] for name, s in table["summary"].items() if s.get("next_against_random")}
    if pairs:
        lines += ["", "`next` against random places on the same sessions: the touches beyond the first each needs "
                  "until its answer is right at confidence >= 0.95 and stays right, or to reach confidence 0.99 "
                  "(mean), how many fewer `next` needs, the sessions each is earlier in, and the Wilcoxon "
                  "signed-rank test's p-value; `next`'s proposals, s.", "",
                  "| set | until | extra touches, next | extra, random | fewer with next | next earlier | "
                  "random earlier | p-value | proposal s median / p95 / max |", "|---|---|---|---|---|---|---|---|---|"]
        for name, both in pairs.items():
            q = table["summary"][name]["next"]["propose_seconds"]
            prop = "-" if q["median"] is None else f"{q['median']:.2f} / {q['p95']:.2f} / {q['max']:.2f}"
            for until, pr in (("right at 0.95", both), ("0.99", both.get("at_0.99") or {})):
                if not pr:
                    continue
                fewer = "-" if pr["fewer_percent"] is None else f"{pr['fewer_percent']:.0f}%"
                pv = "-" if pr["p_value"] is None else f"{pr['p_value']:.3g}"
                lines.append(f"| {name} | {until} | {pr['extra_next']:.2f} | {pr['extra_random']:.2f} | {fewer} | "
                             f"{pr['next_earlier']} | {pr['random_earlier']} | {pv} | {prop} |")
    lines += ["", "Adding a touch to a session of n touches, against the added touch's own recognition: median "
              "(adds).", "", "| set | strategy | " + " | ".join(f"n = {n}" for n in range(1, touches)) + " |",
              "|---|---|" + "---|" * (touches - 1)]
    for name, s in table["summary"].items():
        for strategy in table["strategies"]:
            cells = ["-" if b["median"] is None else f"{b['median']:.2f} ({b['adds']})"
                     for b in s[strategy]["add_over_own_by_touches"]]
            lines.append(f"| {name} | {strategy} | " + " | ".join(cells) + " |")
    lines += ["", "Where the adds' time goes: per stage of an add, the adds that ran it, its share of the adds' "
              "seconds, and its seconds over the added touch's own search (median over the adds that ran it).", "",
              "| set | strategy | adds | " + " | ".join(STAGES) + " |", "|---|---|---|" + "---|" * len(STAGES)]
    for name, s in table["summary"].items():
        for strategy in table["strategies"]:
            st = s[strategy]["add_stages"]
            adds = sum(b["adds"] for b in s[strategy]["add_over_own_by_touches"])
            cells = ["-" if st[k]["share"] is None else
                     f"{st[k]['adds']}, {100 * st[k]['share']:.0f}%, "
                     + ("-" if st[k]["over_own_median"] is None else f"{st[k]['over_own_median']:.2f}")
                     for k in STAGES]
            lines.append(f"| {name} | {strategy} | {adds} | " + " | ".join(cells) + " |")
    lines += ["", "Sessions whose pose of the true model fits the touches as well as the true pose does, after "
              "each touch count (a wrong answer with the true pose found is the data's, not the searches').", "",
              "| set | strategy | " + " | ".join(str(k) for k in range(1, touches + 1)) + " |",
              "|---|---|" + "---|" * touches]
    for name, s in table["summary"].items():
        for strategy in table["strategies"]:
            cells = ["-" if p["truth_found_percent"] is None else f"{p['truth_found_percent']:.0f}%"
                     for p in s[strategy]["per_touches"]]
            lines.append(f"| {name} | {strategy} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
