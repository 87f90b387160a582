"""Touches as patches, as vision-based skins record them (``tactrec bench patch``).

On each scan of a set, ``instances`` patches at vertices no two within 15
rings (P3's sites), each a height map of :data:`~tactrec.simulation.PATCH_POINTS`
pixels over a disc of each radius of :data:`RADII` (mm), depth noise
:data:`NOISE` mm (Gaussian), the gel's blur ``blur`` mm, in a random sensor
frame (:func:`tactrec.simulation.simulate_patch`).  Each is recognised with
``fast`` against the whole set (*known*) and against the set without the
touched scan (*unknown*, its open world: :mod:`.open_world`).  Sets: the ten
``paper-fig11`` scans (``fig11``), the meshes from other sources (``other``,
:mod:`.other_scans`) and, when named, all 78 YCB scans (``ycb``, one patch a
scan and radius per 25 instances, at least one).

Reported per set and radius:

* accuracy (the best model is the touched one), and the **fit-limit
  ceiling** beside it, as ``tactrec bench fit-limit`` counts it: the true
  pose refined on the true scan; a miss is *outfitted* where another scan
  fits the spokes better than every pose known on the true one, a *search
  miss* otherwise, *within the noise* where the winner's and the truth's
  distances differ by less than two standard errors (paired);
  ``clear ceiling`` = 100 - outfitted - search misses within the noise;
* the contact's error (mm) when right: the patch's middle under the found
  pose against the true surface point there; and how many right answers say
  they are located (:attr:`~tactrec.recognition.Recognition.located`), of
  those how many lie farther off than the target;
* the recognition's seconds (median, p95, max);
* on its scan alone (the patch searched with ``among`` the touched scan, as
  a user who knows the object asks where it was touched): how many are
  located within 1 mm, and how many are sure (>= 0.95) of a place farther
  off that the true pose fits clearly better (paired, two standard errors);
* how many wrong answers were sure (probability >= 0.95), and the expected
  calibration error over the known and unknown outcomes mixed one to one,
  with the set's null model of chance fits, calibrated on curves and patches
  of its scans (:mod:`tactrec.chance.fit`); on ``fig11`` and ``other``
  (:data:`OPEN_WORLD`), not the 78, whose null model would take hours.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.atomic import write_text_atomic
from ..registration.result import apply_poses
from .calibration import SURE, ece_if_calibrated, expected_calibration_error
from .common import (CORE_SOURCES, instance_rng, null_model, recognizer, refined_truth, run_parallel, saved_record,
                     sources_hash, write_json)
from .open_world import _percent
from .sensor import _quantiles

__all__ = ["run", "SETS", "RADII", "NOISE", "TARGETS"]

SETS = ("fig11", "other", "ycb")
DEFAULT_SETS = SETS[:2]
#: the sets whose patches are also recognised with their scan left out and scored with the set's null model
#: of chance fits (a null model of the 78 scans, curves and patches, would take hours to fit)
OPEN_WORLD = SETS[:2]
#: the patches' radii, mm
RADII = (2.0, 4.0, 6.0, 10.0)
#: the depth noise's sigma, mm
NOISE = 0.02
#: the issue's targets: 6 mm within 2 points of the clear ceiling, contact within 1 mm, median and
#: p95 seconds on 10 models; 10 mm accuracy on the ten scans and on the 78; the ECE
TARGETS = {"ceiling_points": 2.0, "contact_mm": 1.0, "median_s": 0.3, "p95_s": 1.0, "ten_10mm": 98.0,
           "ycb_10mm": 95.0, "ece": 0.05}


def _code_hash() -> str:
    return sources_hash(*CORE_SOURCES, "simulation.py", "estimation_patch.py", "bench/common.py", "bench/patch.py")


def _models(scans: str) -> tuple[str, ...]:
    from ..surfaces import BUILTIN_SETS
    from .other_scans import OTHER

    return {"fig11": tuple(BUILTIN_SETS["paper-fig11"]), "other": OTHER}.get(scans, ())


def _db(scans: str):
    from .common import database, ycb_database

    return ycb_database() if scans == "ycb" else database(_models(scans))


def _count(scans: str, instances: int) -> int:
    """Patches a scan and radius: ``instances``, on the 78 one per 25 of them (at least one)."""
    return max(1, -(-instances // 25)) if scans == "ycb" else instances


def patch_touch(entry, m_index: int, instance: int, seed: int, radius: float, blur: float = 0.0,
                stated: bool = False):
    """The bench's patch on ``entry``: at the instance's spread vertex, or the next one whose disc
    sees enough surface (on a mesh too coarse for that many spread vertices, at seeded random ones), its
    noise stated in the map where ``stated``: ``(vertex, data)``, ``(None, None)`` where none does (a
    model too small or thin for the patch)."""
    from ..simulation import simulate_patch, spread_vertices

    vertices = spread_vertices(entry.model, instance + 8, rings=15, rng=instance_rng(seed, m_index))
    rng = instance_rng(seed, m_index, instance, int(radius * 10))
    if len(vertices) < instance + 8:           # a coarse mesh runs out of spread vertices: then any, seeded
        vertices = np.concatenate([vertices, rng.permutation(len(entry.model.vertices))[:instance + 50]])
    for k in range(instance, len(vertices)):
        try:
            return int(vertices[k]), simulate_patch(entry.model, [int(vertices[k])], radius=radius, noise=NOISE,
                                                    blur=blur, stated=stated, rng=rng)
        except ValueError:
            continue
    return None, None                          # no place of this model takes a patch so large


def _touch(task) -> dict:
    from .fit_limit import paired_gap, registered_distances

    scans, m_index, instance, seed, radius, blur, stated = task
    db = _db(scans)
    entry = db.entries[m_index]
    vertex, touch = patch_touch(entry, m_index, instance, seed, radius, blur, stated)
    if touch is None:                          # no sensor records such a patch of this model: counted apart
        return {"scans": scans, "model": entry.name, "instance": instance, "radius": radius, "blur": blur,
                "no_place": True}
    r = recognizer(db.entries)
    known = r.recognize(touch)
    # the open world is measured on the sets whose null models cost minutes (OPEN_WORLD), not on the 78
    unknown = r.recognize(touch, among=[e.name for e in db.entries if e is not entry]) if scans in OPEN_WORLD else None
    errors = {x.model: x.error / x.scale for x in known.ranking if x.ok}
    R, t, truth_error, scale = refined_truth(entry, touch)
    own = min(truth_error, errors.get(entry.name, np.inf))
    others = min((e for name, e in errors.items() if name != entry.name), default=np.inf)
    correct = known.best == entry.name
    contact = gap = None
    x = np.asarray(touch.points, dtype=np.float64)
    on_truth = entry.model.distance(apply_poses(R, t, x * scale)[0]) / scale
    win = known.registration
    if win is not None:
        on_winner = registered_distances(db.get(win.model).model, win, x)
        gap = paired_gap(on_winner, on_truth)          # right and far: whether the data tell the places apart
    if correct:
        contact = _off(win, touch)
    # where a user who knows the object asks where the patch lies on it: the scan alone searched
    alone = r.recognize(touch, among=[entry.name])
    mine = alone.registration
    alone_mm = alone_gap = None
    if mine is not None:
        alone_mm = _off(mine, touch)
        alone_gap = paired_gap(registered_distances(entry.model, mine, x), on_truth)
    return {"scans": scans, "model": entry.name, "instance": instance, "radius": radius, "blur": blur,
            "vertex": vertex, "points": len(touch.patch.points), "noise_estimate": float(known.touch.noise),
            "recognized": known.best, "correct": correct, "ambiguous": known.ambiguous,
            "seconds": known.seconds, "contact_mm": contact, "truth_error": truth_error,
            "kind": "correct" if correct else ("outfitted" if others < own else "search miss"),
            "gap_se": gap, "within_noise": gap is not None and abs(gap) < 2.0,
            "located": None if contact is None else bool(contact <= TARGETS["contact_mm"]),
            "says_located": bool(known.located), "place": float(known.place),
            "alone_mm": alone_mm, "alone_gap_se": alone_gap, "alone_confidence": float(alone.confidence),
            "known": _evidence(known), "unknown": None if unknown is None else _evidence(unknown),
            "unknown_seconds": None if unknown is None else unknown.seconds}


def _off(registration, touch) -> float:
    """How far ``registration`` places the patch's contact from where it was taken (the data's units)."""
    found = registration.scale * (registration.rotation @ touch.contact) + registration.translation
    return float(np.linalg.norm(found - np.asarray(touch.meta["truth"]["contact"])) / registration.scale)


def _evidence(rec) -> dict | None:
    return None if rec.evidence is None else rec.evidence.to_json()


def _saved(job):
    task, folder = job
    name = "-".join(str(x) for x in task)
    return saved_record(folder / f"{name}.json", lambda: _touch(task))


def _calibration(rows: list[dict], chance) -> dict:
    """The known and unknown outcomes of ``rows`` mixed one to one, scored with ``chance`` (the set's
    null model; None: the fit test alone): sure and wrong, unknown on top, the ECE and its floor."""
    from .open_world import outcome

    known = [outcome(r["known"], chance=chance) + (r["model"],) for r in rows]
    unknown = [outcome(r["unknown"], chance=None if chance is None else chance.without([r["model"]]))
               for r in rows]
    conf = [k[1] for k in known] + [u[1] for u in unknown]
    right = [k[0] == k[3] for k in known] + [u[0] == "unknown" for u in unknown]
    return {"sure_wrong": sum(c >= SURE and not ok for c, ok in zip(conf, right)),
            "open_known_percent": _percent(k[0] == k[3] for k in known),
            "unknown_top_percent": _percent(u[0] == "unknown" for u in unknown),
            "ece": expected_calibration_error(conf, right), "ece_if_calibrated": ece_if_calibrated(conf)}


def _summary(rows: list[dict], chance, open_world: bool = True) -> dict:
    n = max(len(rows), 1)
    count = {k: sum(r["kind"] == k for r in rows) for k in ("correct", "outfitted", "search miss")}
    clear = [r for r in rows if r["kind"] == "search miss" and not r["within_noise"]]
    return {"touches": len(rows), "accuracy_percent": 100.0 * count["correct"] / n,
            "ceiling_percent": 100.0 - 100.0 * count["outfitted"] / n,
            "clear_ceiling_percent": 100.0 - 100.0 * (count["outfitted"] + sum(
                r["within_noise"] for r in rows if r["kind"] == "search miss")) / n,
            "clear_search_misses": len(clear),
            "contact_mm": _quantiles([r["contact_mm"] for r in rows]),
            "located_percent": _percent([r["located"] for r in rows if r["correct"]]),
            "far_within_noise": sum(r["correct"] and not r["located"] and r["within_noise"] for r in rows),
            "far_clear": sum(r["correct"] and not r["located"] and not r["within_noise"] for r in rows),
            # what the answer says of its place: located, and of those, how many lie beyond the target
            "says_located": sum(r["correct"] and bool(r.get("says_located")) for r in rows),
            "says_located_far": sum(r["correct"] and bool(r.get("says_located")) and not r["located"] for r in rows),
            "seconds": _quantiles([r["seconds"] for r in rows]),
            "alone_located_percent": _percent([r["alone_mm"] is not None and r["alone_mm"] <= TARGETS["contact_mm"]
                                               for r in rows]),
            # sure of a place more than the target off that the truth clearly fits better
            "alone_sure_far": sum(r["alone_confidence"] >= SURE and r["alone_mm"] is not None
                                  and r["alone_mm"] > TARGETS["contact_mm"] and r["alone_gap_se"] >= 2.0
                                  for r in rows),
            "calibration": _calibration(rows, chance) if open_world else None,
            "fit_test": _calibration(rows, None) if open_world else None}


def run(*, out, instances: int = 3, seed: int = 0, jobs: int | None = None, quiet: bool = False,
        sets=DEFAULT_SETS, radii=RADII, blur: float = 0.0, stated: bool = False, **_ignored) -> dict:
    """Recognise the patches of ``sets`` at ``radii``; write ``patch.json`` and ``patch.md``."""
    out = Path(out)
    folder = out / "patch.parts" / _code_hash()
    folder.mkdir(parents=True, exist_ok=True)
    tasks = []
    for scans in sets:
        n = len(_db(scans).entries) if scans == "ycb" else len(_models(scans))
        count = _count(scans, instances)
        tasks += [(scans, m, i, seed, float(r), float(blur), bool(stated)) for r in radii for m in range(n)
                  for i in range(count)]
    records = run_parallel(_saved, [(t, folder) for t in tasks], jobs=jobs or 1, quiet=quiet, desc="patch")
    summary = {}
    for scans in sets:
        chance = null_model(_db(scans).entries, kinds=("curves", "patch")) if scans in OPEN_WORLD else None
        for r in radii:
            rows = [x for x in records if x["scans"] == scans and x["radius"] == float(r)]
            summary[f"{scans}/{r:g}"] = dict(_summary([x for x in rows if not x.get("no_place")], chance,
                                                      open_world=scans in OPEN_WORLD),
                                             no_place=sum(bool(x.get("no_place")) for x in rows))
    table = {"benchmark": "patch", "method": "fast", "instances": instances, "seed": seed, "noise": NOISE,
             "blur": blur, "stated": bool(stated), "targets": TARGETS, "summary": summary, "records": records}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "patch.json", table)
    table["text"] = _text(table, sets, radii)
    write_text_atomic(out / "patch.md", table["text"])
    return table


def _text(table: dict, sets, radii) -> str:
    s = table["summary"]
    ycb = f" ({_count('ycb', table['instances'])} on the 78)" if "ycb" in sets else ""
    lines = [f"fast, seed {table['seed']}, {table['instances']} patches per scan and radius{ycb}, depth noise "
             f"{table['noise']} mm{' (stated in each map)' if table.get('stated') else ''}, blur {table['blur']} mm.",
             "",
             "| set | radius mm | touches (no place) | right | clear ceiling | ceiling | clear search misses | "
             "located (<= 1 mm) | "
             "far: within the noise / clear | says located: all / farther | contact mm (median/p95/max) | "
             "s (median/p95/max) | its scan alone: located (<= 1 mm) / sure, farther and clearly worse |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    q = lambda v, f: "-" if v is None else "/".join(f"{x:{f}}" for x in v)   # noqa: E731
    p = lambda v: "-" if v is None else f"{v:.0f}%"                          # noqa: E731
    for scans in sets:
        for r in radii:
            x = s[f"{scans}/{r:g}"]
            lines.append(f"| {scans} | {r:g} | {x['touches']} ({x['no_place']}) | {x['accuracy_percent']:.1f}% | "
                         f"{x['clear_ceiling_percent']:.1f}% | {x['ceiling_percent']:.1f}% | "
                         f"{x['clear_search_misses']} | {p(x['located_percent'])} | {x['far_within_noise']} / "
                         f"{x['far_clear']} | {x['says_located']} / {x['says_located_far']} | "
                         f"{q(x['contact_mm'], '.2f')} | {q(x['seconds'], '.2f')} | "
                         f"{p(x['alone_located_percent'])} / {x['alone_sure_far']} |")
    if not any(x in OPEN_WORLD for x in sets):
        return "\n".join(lines) + "\n"
    lines += ["", "Known and unknown (the scan left out) mixed one to one, with the set's null model of chance fits, "
              "and by the fit test alone:", "",
              "| set | radius mm | sure and wrong | right in the open world | unknown on top | ECE (if calibrated) | "
              "fit test alone: sure and wrong | ECE |", "|---|---|---|---|---|---|---|---|"]
    for scans in [x for x in sets if x in OPEN_WORLD]:
        for r in radii:
            c, f = s[f"{scans}/{r:g}"]["calibration"], s[f"{scans}/{r:g}"]["fit_test"]
            lines.append(f"| {scans} | {r:g} | {c['sure_wrong']} | {p(c['open_known_percent'])} | "
                         f"{p(c['unknown_top_percent'])} | {c['ece']:.3f} ({c['ece_if_calibrated']:.3f}) | "
                         f"{f['sure_wrong']} | {f['ece']:.3f} |")
    return "\n".join(lines) + "\n"
