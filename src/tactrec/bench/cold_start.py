"""One touch, one new process (``tactrec bench cold-start``).

A robot's script may call ``tactrec recognize touch.json --db DB`` once per
touch.  This benchmark builds the database of the ten ``paper-fig11`` scans
(once, in ``out``, with no tip radius), writes ``instances`` P3 touches (one
per scan, in turn; the touches of ``fast-vs-paper``), and runs the command in
a new process for each: it reports the recognition's own time (the
``seconds`` of the result) and the command's wall time, median, p95 and max.
The same touches then come from a round tip of each radius of ``TIPS`` (the
points are its centres, the file says the radius), each in a new process on
that database: a radius the database was not built for, whose offset fields
the first touch of every process would otherwise build.  Their times are
reported beside the plain touches', as ratios of medians measured in the
same run.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from ..database import build_database
from ..io.atomic import write_text_atomic
from ..io.touch import save_touch
from ..surfaces import BUILTIN_SETS
from .common import spread, write_json
from .common import database, simulate

__all__ = ["run", "TIPS"]

#: the tip radii (mm) of the touches recognised on the database built without them
TIPS = (1.0, 2.0, 5.0)


def _recognized(path: Path, db_path: Path) -> tuple[dict, float]:
    """``tactrec recognize`` of the touch ``path`` on ``db_path`` in a new process: its result and the
    command's wall time."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "tactrec", "recognize", str(path), "--db", str(db_path),
                           "--json", "--quiet"], capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"tactrec recognize failed on {path}: {done.stderr.strip()[-300:]}")
    return json.loads(done.stdout), wall


def run(*, out, instances: int = 10, seed: int = 0, quiet: bool = False, **_ignored) -> dict:
    """Run ``tactrec recognize`` in a new process per touch, plain and with each tip of :data:`TIPS`;
    write ``cold-start.json`` and ``.md``."""
    from ..sensor import Imperfections

    out = Path(out)
    models = BUILTIN_SETS["paper-fig11"]
    db_path = out / "cold-start.db"
    build_database(models, db_path, quiet=True)
    db = database(tuple(models))
    rows = []
    for tip in (0.0,) + TIPS:
        for k in range(instances):
            m_index, instance = k % len(models), k // len(models)
            entry = db.entries[m_index]
            kind = "p3" if tip == 0 else f"p3-tip{tip:g}"
            path = out / "cold-start.touches" / f"{kind}-{entry.name}-{instance}-s{seed}.json"
            path.parent.mkdir(parents=True, exist_ok=True)
            sensor = Imperfections(tip_radius=tip) if tip > 0 else None
            save_touch(simulate(entry, m_index, instance, seed, "p3", sensor)[1], path)
            result, wall = _recognized(path, db_path)
            rows.append({"file": path.name, "model": entry.name, "tip": tip, "recognized": result["best"],
                         "seconds": result["seconds"], "wall": wall})
    plain = [r for r in rows if r["tip"] == 0]
    table = {"benchmark": "cold-start", "instances": instances, "seed": seed, "models": list(models),
             "seconds": spread([r["seconds"] for r in plain]), "wall": spread([r["wall"] for r in plain]),
             "correct": sum(r["recognized"] == r["model"] for r in plain), "tips": {}, "records": rows}
    for tip in TIPS:
        chosen = [r for r in rows if r["tip"] == tip]
        s, w = spread([r["seconds"] for r in chosen]), spread([r["wall"] for r in chosen])
        table["tips"][f"{tip:g}"] = {"seconds": s, "wall": w, "correct": sum(r["recognized"] == r["model"] for r in chosen),
                                     "seconds_ratio": s["median"] / table["seconds"]["median"],
                                     "wall_ratio": w["median"] / table["wall"]["median"]}
    write_json(out / "cold-start.json", table)
    s, w = table["seconds"], table["wall"]
    lines = [f"{instances} P3 touches, each 'tactrec recognize --db' in a new process against the ten "
             f"scans: recognition median {s['median']:.3f} s (p95 {s['p95']:.3f}, max {s['max']:.3f}); "
             f"whole command median {w['median']:.2f} s (p95 {w['p95']:.2f}, max {w['max']:.2f}); "
             f"{table['correct']} of {instances} correct"]
    for tip, x in table["tips"].items():
        lines.append(f"the same touches from a {tip} mm tip (the database built without it): recognition median "
                     f"{x['seconds']['median']:.3f} s (p95 {x['seconds']['p95']:.3f}, max {x['seconds']['max']:.3f}), "
                     f"{x['seconds_ratio']:.2f}x the plain median; whole command median {x['wall']['median']:.2f} s, "
                     f"{x['wall_ratio']:.2f}x; {x['correct']} of {instances} correct")
    table["text"] = "\n".join(lines)
    write_text_atomic(out / "cold-start.md", table["text"] + "\n")
    return table
