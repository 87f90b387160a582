"""``tactrec bench serve``: what a request to ``tactrec serve`` costs beyond its recognition.

A real service process (``tactrec serve --models`` the ten ``paper-fig11`` scans, method ``fast``)
gets one P3 touch per request (:func:`tactrec.bench.common.vertex_touch`: 81 points per curve, 60
degrees, at vertices spread over each scan; ``instances`` per model), each sent once the last
answer has come.  Per request the table gives the round trip as the client sees it (writing the
line to reading the answer) and the recognition's own ``seconds`` (the answer's), and the
difference: the service's cost (reading and checking the request, writing the answer, the pipes).
A first request, not counted, warms the process.  Median, p95 and max of each.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from .common import scan_database, spread, write_json
from .common import vertex_touch

__all__ = ["run", "TARGET_MS"]

#: the target of a request's cost beyond its recognition, milliseconds (median)
TARGET_MS = 20.0


def run(*, out: Path, instances: int, seed: int, jobs=None, quiet: bool = True, **_) -> dict:
    from ..surfaces import BUILTIN_SETS

    names = BUILTIN_SETS["paper-fig11"]
    entries = scan_database(tuple(names)).entries
    touches = [(e.name, vertex_touch(e, m, i, seed)[1]) for m, e in enumerate(entries) for i in range(instances)]
    proc = subprocess.Popen([sys.executable, "-m", "tactrec", "serve", "--models", *names, "--method", "fast",
                             "--quiet"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    rows = []
    try:
        for k, (name, data) in enumerate([touches[0]] + touches):
            line = json.dumps({"id": k, "recognize": data.to_json()}) + "\n"
            start = time.perf_counter()
            proc.stdin.write(line)
            proc.stdin.flush()
            answer = json.loads(proc.stdout.readline())
            trip = time.perf_counter() - start
            if "error" in answer:
                raise RuntimeError(f"the service refused a benchmark touch: {answer['error']}")
            if k > 0:
                rows.append({"model": name, "recognized": answer["best"], "trip_seconds": trip,
                             "seconds": answer["seconds"], "overhead_ms": 1e3 * (trip - answer["seconds"])})
            if not quiet:
                print(f"\r{k}/{len(touches)}", end="", file=sys.stderr, flush=True)
    finally:
        proc.stdin.close()
        proc.wait(timeout=120)
    overhead = spread([r["overhead_ms"] for r in rows])
    recognition = spread([r["seconds"] for r in rows])
    right = sum(r["recognized"] == r["model"] for r in rows)
    table = {"benchmark": "serve", "method": "fast", "requests": len(rows), "seed": seed, "target_ms": TARGET_MS,
             "overhead_ms": overhead, "recognition_seconds": recognition,
             "trip_seconds": spread([r["trip_seconds"] for r in rows]), "right": right, "rows": rows}
    table["text"] = "\n".join([
        f"tactrec serve, {len(rows)} P3 requests on the ten paper-fig11 scans (fast), one at a time",
        f"  beyond the recognition: median {overhead['median']:.2f} ms, p95 {overhead['p95']:.2f} ms, "
        f"max {overhead['max']:.2f} ms (target: median <= {TARGET_MS:g} ms)",
        f"  the recognition itself: median {recognition['median']:.3f} s, p95 {recognition['p95']:.3f} s, "
        f"max {recognition['max']:.3f} s; right {right}/{len(rows)}"])
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "serve.json", table)
    return table
