"""Recognition (Section 3.3) on simulated touches: protocols P1 and P2 in small."""

import numpy as np
import pytest
from tactrec.database import build_entries
from tactrec.recognition import recognize
from tactrec.simulation import simulate_random_touch

P = dict(points=61, spacing=0.02, angle=60.0, noise=0.001)   # the benchmarks' P1/P2 settings


@pytest.mark.slow
def test_p2_in_small_every_touch_recognised(table1):
    """Two seeded instances per Table 1 surface, recognised among the four (P2)."""
    for s, entry in enumerate(table1.entries):
        for i in range(2):
            touch = simulate_random_touch(entry.model, rng=np.random.default_rng((11, s, i)), **P)
            result = recognize(touch, table1)
            assert result.best == entry.name, (entry.name, i, [(r.model, r.error) for r in result.ranking])
            err = entry.model.location_error(result.registration.location, touch.meta["truth"]["contact"])
            assert err < 0.05


def test_ranking_order_and_json(table1):
    entry = table1.get("monkey-saddle")
    touch = simulate_random_touch(entry.model, rng=3, **P)
    result = recognize(touch, table1)
    out = result.to_json()
    assert out["best"] == "monkey-saddle" == out["ranking"][0]["model"]
    errors = [r["error"] for r in out["ranking"] if r["error"] is not None]
    assert errors == sorted(errors)
    seen_rejected = False
    for r in out["ranking"]:
        seen_rejected |= r["error"] is None
        if seen_rejected:
            assert r["error"] is None and r["rejected"]
    R = np.array(out["ranking"][0]["rotation"])
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-9)
    assert set(out) >= {"best", "ranking", "contact", "normal", "curvatures", "seconds"}


def test_without_outward_hint_both_normals_are_tried(table1):
    entry = table1.get("crossed-trough")
    touch = simulate_random_touch(entry.model, outward=False, rng=5, **P)
    assert touch.outward is None
    result = recognize(touch, table1)
    assert result.best == "crossed-trough"
    truth = touch.meta["truth"]
    assert entry.model.location_error(result.registration.location, truth["contact"]) < 0.05


def test_units_are_converted():
    """A touch recorded in metres on the 33 mm sphere is recognised among the mm objects."""
    db = build_entries(["sphere-33", "cylinder-50"])
    sphere = db.get("sphere-33").model
    touch = simulate_random_touch(sphere, points=41, spacing=0.5, noise=0.005, rng=2)
    in_metres = touch.transformed(np.eye(3), np.zeros(3), scale=1e-3)
    in_metres = type(touch).from_arrays(list(in_metres.curves), outward=in_metres.outward, units="m")
    result = recognize(in_metres, db)
    assert result.best == "sphere-33"
    best = result.registration
    assert np.isclose(best.scale, 1000.0)
    mapped = best.scale * in_metres.points @ best.rotation.T + best.translation
    assert np.mean(sphere.distance(mapped)) < 0.01
