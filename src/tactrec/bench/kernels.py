"""The same answer on every CPU (``tactrec bench kernels``).

OpenBLAS picks a kernel per CPU (``OPENBLAS_CORETYPE``), and the kernels round
differently.  This benchmark writes the touches of ``fast-vs-paper`` (both
protocols, the same seeds) to files once, then recognises the same files with
``fast`` in one process per kernel (``Haswell`` and ``Prescott`` by default)
and compares: on every touch that neither run flags ambiguous, the best model
must be the same and the two contacts within 0.1 mm.  It also reports how many
results agree exactly (the same best model and error to 1e-9 relative).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from ..io.atomic import write_text_atomic
from ..io.touch import save_touch
from ..surfaces import BUILTIN_SETS
from .common import write_json
from .common import PROTOCOLS, database, simulate

__all__ = ["run", "KERNELS", "CONTACT_MM"]

KERNELS = ("Haswell", "Prescott")
#: the largest distance between the contacts of two runs that counts as the same place, mm
CONTACT_MM = 0.1


def _touch_files(folder: Path, models, instances: int, seed: int, protocols) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    db = database(models)
    paths = []
    for protocol in protocols:
        for m_index, entry in enumerate(db.entries):
            for i in range(instances):
                path = folder / f"{protocol}-{entry.name}-{i}-s{seed}.json"
                if not path.exists():
                    save_touch(simulate(entry, m_index, i, seed, protocol)[1], path)
                paths.append(path)
    return paths


def _in_kernel(kernel: str, models, paths: list[Path], out: Path) -> list[dict]:
    """Recognise ``paths`` in a new process under ``kernel``; its results, one per path."""
    env = dict(os.environ, OPENBLAS_CORETYPE=kernel)
    listing = out / f"kernels-{kernel}.in"
    write_text_atomic(listing, json.dumps({"models": list(models), "paths": [str(p) for p in paths]}))
    result = subprocess.run([sys.executable, "-m", "tactrec.bench.kernels", str(listing)], env=env,
                            capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"the run under {kernel} failed: {result.stderr.strip()[-400:]}")
    return [json.loads(line) for line in result.stdout.splitlines() if line.startswith("{")]


def _child(listing: str) -> None:
    from ..io.touch import load_touch
    from ..recognition import Recognizer, default_workers

    job = json.loads(Path(listing).read_text(encoding="utf-8"))
    db = database(tuple(job["models"]))
    with Recognizer(db.entries, workers=default_workers()) as recognizer:
        for path in job["paths"]:
            r = recognizer.recognize(load_touch(path))
            reg = r.registration
            print(json.dumps({"file": Path(path).name, "best": r.best, "ambiguous": r.ambiguous,
                              "error": None if reg is None else reg.error / reg.scale,
                              "location": None if reg is None else reg.location.tolist(),
                              "seconds": r.seconds}), flush=True)


def _compare(a: dict, b: dict) -> dict:
    same_model = a["best"] == b["best"]
    gap = (float(np.linalg.norm(np.subtract(a["location"], b["location"])))
           if same_model and a["location"] is not None else None)
    exact = same_model and a["error"] is not None and abs(a["error"] - b["error"]) <= 1e-9 * max(a["error"], 1e-12)
    flagged = a["ambiguous"] or b["ambiguous"]
    return {"file": a["file"], "best": [a["best"], b["best"]], "ambiguous": flagged, "contact_gap_mm": gap,
            "exact": bool(exact), "agrees": bool(flagged or (same_model and gap is not None and gap < CONTACT_MM))}


def run(*, out, instances: int = 10, seed: int = 0, quiet: bool = False, models: tuple[str, ...] | None = None,
        protocols=tuple(PROTOCOLS), kernels=KERNELS, **_ignored) -> dict:
    """Recognise the fast-vs-paper touches under each kernel; write ``kernels.json`` and ``.md``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    models = tuple(models or BUILTIN_SETS["paper-fig11"])
    paths = _touch_files(out / "kernels.touches", models, instances, seed, protocols)
    runs = {k: _in_kernel(k, models, paths, out) for k in kernels}
    first, second = (runs[k] for k in kernels[:2])
    rows = [_compare(a, b) for a, b in zip(first, second)]
    unflagged = [r for r in rows if not r["ambiguous"]]
    table = {"benchmark": "kernels", "kernels": list(kernels), "instances": instances, "seed": seed,
             "models": list(models), "touches": len(rows), "not_ambiguous": len(unflagged),
             "disagreements": [r for r in rows if not r["agrees"]],
             "same_best_unflagged": sum(r["best"][0] == r["best"][1] for r in unflagged),
             "contacts_within_0.1mm_unflagged": sum(r["contact_gap_mm"] is not None
                                                    and r["contact_gap_mm"] < CONTACT_MM for r in unflagged),
             "exactly_equal": sum(r["exact"] for r in rows), "records": rows, "runs": runs}
    write_json(out / "kernels.json", table)
    text = (f"{len(rows)} touches (fast-vs-paper, seed {seed}) recognised under {' and '.join(kernels)}: "
            f"{table['not_ambiguous']} not flagged ambiguous, of which {table['same_best_unflagged']} with the same "
            f"best model and {table['contacts_within_0.1mm_unflagged']} with contacts within {CONTACT_MM} mm; "
            f"{len(table['disagreements'])} disagreements; {table['exactly_equal']} results equal to 1e-9.")
    write_text_atomic(out / "kernels.md", text + "\n")
    table["text"] = text
    return table


if __name__ == "__main__":
    _child(sys.argv[1])
