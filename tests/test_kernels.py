"""The answers do not depend on the CPU's BLAS kernel.

OpenBLAS picks its kernels by CPU (``OPENBLAS_CORETYPE`` overrides the choice), and kernels round
differently.  The same touches, simulated and recognised under two kernels, must give the same
results to the last bit: a P3 and a hard noisy touch on two scans, a closed-form touch, a tip's and
one with outliers, a touch with method ``paper``, a two-touch session with ``next``'s proposal
after each touch, and 24 noisy touches without an outward side on the four small meshes (ambiguous
answers included).
"""

import json
import os
import subprocess
import sys

SCRIPT = r"""
import json
import sys
import numpy as np
from tactrec.bench.answers import HARD, P3, without_timings as clean
from tactrec.bench.common import random_face_site, random_site_touch
from tactrec.database import build_entries
from tactrec.recognition import Recognizer
from tactrec.sensor import Imperfections
from tactrec.simulation import random_rigid_motion, sensor_to_world, simulate_random_touch, simulate_touch

scans = build_entries(["banana", "mug"]).entries
closed = build_entries(["ellipsoid", "monkey-saddle"]).entries
out = {}


with Recognizer(scans, workers=1) as rec:
    for k, e in enumerate(scans):
        for protocol, spec in (("p3", P3), ("hard", HARD)):
            touch = random_site_touch(e.model, np.random.default_rng([k, protocol == "hard"]), spec,
                                      vertex=protocol == "p3")
            out[f"{protocol}-{e.name}"] = [clean(touch.curves), clean(rec.recognize(touch).to_json())]
    for k, (label, imperfections) in enumerate((("tip", Imperfections(tip_radius=1.0)),
                                                 ("outliers", Imperfections(outliers=0.04)))):
        touch = random_site_touch(scans[k].model, np.random.default_rng([7, k]), dict(P3, outward=False),
                                  imperfections=imperfections)
        out[f"{label}-{scans[k].name}"] = [clean(touch.curves), clean(rec.recognize(touch).to_json())]
    model = scans[1].model
    rng = np.random.default_rng(11)
    model2world = random_rigid_motion(rng, extent=200.0)
    session, steps = rec.session(), []
    while len(steps) < 2:
        try:
            touch = simulate_touch(model, random_face_site(model, rng), rng=rng, **HARD)
        except ValueError:
            continue
        result = session.add(touch, sensor_to_world(touch, model2world))
        proposal = session.next(radius=40.0, angle=30.0, rng=len(steps))
        steps.append([clean(result.to_json()), clean(proposal.to_json())])
    out["session-mug"] = steps
with Recognizer(scans, workers=1, method="paper") as rec:
    touch = random_site_touch(scans[0].model, np.random.default_rng(5), P3, vertex=True)
    out["paper-banana"] = clean(rec.recognize(touch).to_json())
with Recognizer(closed, workers=1) as rec:
    touch = simulate_random_touch(closed[0].model, spacing=0.02, points=41, noise=0.001,
                                  rng=np.random.default_rng(3))
    out["closed-form-ellipsoid"] = [clean(touch.curves), clean(rec.recognize(touch).to_json())]
sys.path.insert(0, TESTS)
from conftest import small_meshes
small = small_meshes()
with Recognizer(small, workers=1) as rec:
    for m, entry in enumerate(small):
        for i in range(6):
            touch = simulate_random_touch(entry.model, rng=np.random.default_rng((21, m, i)), points=41, spacing=0.3,
                                          angle=60.0, noise=0.02, noise_kind="gaussian", outward=False)
            found = rec.recognize(touch)
            out[f"small-{entry.name}-{i}"] = [clean(touch.curves), found.best, found.ambiguous,
                                              found.registration.location.tolist()]
print(json.dumps(out, sort_keys=True, allow_nan=True))
"""


def _run(coretype: str) -> subprocess.Popen:
    env = dict(os.environ, OPENBLAS_CORETYPE=coretype, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    script = f"TESTS = {os.path.dirname(os.path.abspath(__file__))!r}\n" + SCRIPT
    return subprocess.Popen([sys.executable, "-c", script], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def test_results_are_the_same_under_every_blas_kernel():
    runs = {kind: _run(kind) for kind in ("Haswell", "Prescott")}
    outputs = {}
    for kind, proc in runs.items():
        stdout, stderr = proc.communicate(timeout=600)
        assert proc.returncode == 0, stderr[-2000:]
        outputs[kind] = stdout
    answers = json.loads(outputs["Haswell"])
    assert len(answers) == 9 + 24 and all(answers.values())
    assert outputs["Haswell"] == outputs["Prescott"]
