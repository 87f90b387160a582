"""One touch, one new process (``tactrec bench cold-start``).

A robot's script may call ``tactrec recognize touch.json --db DB`` once per
touch.  This benchmark builds the database of the ten ``paper-fig11`` scans
(once, in ``out``), writes ``instances`` P3 touches (one per scan, in turn;
the touches of ``fast-vs-paper``), and runs the command in a new process for
each: it reports the recognition's own time (the ``seconds`` of the result)
and the command's wall time, median, p95 and max.
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
from .fast_vs_paper import _database, _simulate

__all__ = ["run"]


def run(*, out, instances: int = 10, seed: int = 0, quiet: bool = False, **_ignored) -> dict:
    """Run ``tactrec recognize`` in a new process per touch; write ``cold-start.json`` and ``.md``."""
    out = Path(out)
    models = BUILTIN_SETS["paper-fig11"]
    db_path = out / "cold-start.db"
    build_database(models, db_path, quiet=True)
    db = _database(tuple(models))
    rows = []
    for k in range(instances):
        m_index, instance = k % len(models), k // len(models)
        entry = db.entries[m_index]
        path = out / "cold-start.touches" / f"p3-{entry.name}-{instance}-s{seed}.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        save_touch(_simulate(entry, m_index, instance, seed, "p3")[1], path)
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "tactrec", "recognize", str(path), "--db", str(db_path),
                               "--json", "--quiet"], capture_output=True, text=True, check=False)
        wall = time.perf_counter() - start
        if done.returncode != 0:
            raise RuntimeError(f"tactrec recognize failed on {path}: {done.stderr.strip()[-300:]}")
        result = json.loads(done.stdout)
        rows.append({"file": path.name, "model": entry.name, "recognized": result["best"],
                     "seconds": result["seconds"], "wall": wall})
    table = {"benchmark": "cold-start", "instances": instances, "seed": seed, "models": list(models),
             "seconds": spread([r["seconds"] for r in rows]), "wall": spread([r["wall"] for r in rows]),
             "correct": sum(r["recognized"] == r["model"] for r in rows), "records": rows}
    write_json(out / "cold-start.json", table)
    s, w = table["seconds"], table["wall"]
    table["text"] = (f"{instances} P3 touches, each 'tactrec recognize --db' in a new process against the ten "
                     f"scans: recognition median {s['median']:.3f} s (p95 {s['p95']:.3f}, max {s['max']:.3f}); "
                     f"whole command median {w['median']:.2f} s (p95 {w['p95']:.2f}, max {w['max']:.2f}); "
                     f"{table['correct']} of {instances} correct")
    write_text_atomic(out / "cold-start.md", table["text"] + "\n")
    return table
