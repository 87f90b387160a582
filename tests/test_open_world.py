"""The open world (tactrec.probability): how sure a touch is of coming from none of the models."""

from __future__ import annotations

import numpy as np
import pytest
from tactrec.estimation import noise_level
from tactrec.probability import (CONSISTENT_SE, NOISE_VARIANCE, SEARCH_MISS, UNKNOWN_PRIOR, evidence, fit_spread,
                                 open_world)
from tactrec.recognition import Recognizer
from tactrec.simulation import simulate_random_touch


def test_the_noise_estimates_spread_is_the_stated_one():
    """The noise estimate over three curves of 41 points of white Gaussian noise: its relative variance
    times the points is NOISE_VARIANCE within 10% (2,000 seeded draws)."""
    rng = np.random.default_rng(5)
    s = np.array([np.median([noise_level(rng.normal(size=(41, 3))) for _ in range(3)]) for _ in range(2000)])
    assert abs(s.std() ** 2 * 123 / NOISE_VARIANCE - 1.0) < 0.1
    assert abs(s.mean() - 1.0) < 0.02


def test_a_true_models_fit_passes_the_test_at_its_stated_rate():
    """A fixed plane under Gaussian noise on every coordinate: the mean distance of 123 points, measured against the limit
    from each draw's own noise estimate, in fit_spread units, has a standard deviation near 1 and lies
    beyond CONSISTENT_SE standard errors on at most 1% of 2,000 draws."""
    rng = np.random.default_rng(6)
    z = []
    for _ in range(2000):
        curves = [np.column_stack([np.linspace(0, 12, 41), np.zeros(41), np.zeros(41)]) +
                  rng.normal(0.0, 0.05, (41, 3)) for _ in range(3)]
        sigma = float(np.median([noise_level(c) for c in curves]))
        limit = sigma * np.sqrt(2 / np.pi)
        mean = np.mean(np.abs(np.concatenate(curves)[:, 2]))
        z.append((mean - limit) / fit_spread(limit, 123))
    z = np.array(z)
    assert 0.8 < z.std() < 1.2 and abs(z.mean()) < 0.2
    assert np.mean(z > CONSISTENT_SE) <= 0.01


def test_open_world_rule():
    """Probabilities sum to 1 with unknown; a model within the noise leaves unknown below 2% (about
    prior exp(-CONSISTENT_SE^2 / 2) / (1 - prior)); one at the
    test's edge never takes more than 1 - prior; far beyond it, unknown takes it all; a prior of 0 is a
    closed world; the two models' shares are kept between them."""
    for z in (-2.0, 0.0, 2.0, CONSISTENT_SE, 5.0, 40.0, 1e6):
        p, u = open_world(np.array([0.7, 0.3]), np.array([z, z + 1.0]))
        assert abs(p.sum() + u - 1.0) < 1e-12 and np.all(p >= 0)
        if z <= 0:
            assert u < 0.02 and p[0] / p[1] > 2.0
        if z >= CONSISTENT_SE:
            assert p.max() <= 1.0 - UNKNOWN_PRIOR + 1e-12
        if z >= 40:
            far = (1 - UNKNOWN_PRIOR) * SEARCH_MISS / ((1 - UNKNOWN_PRIOR) * SEARCH_MISS + UNKNOWN_PRIOR)
            assert abs(p.sum() - far) < 1e-9                  # the search may have missed: never sure of unknown
    p, u = open_world(np.array([1.0]), np.array([40.0]), miss=0.0)
    assert u > 1 - 1e-12
    p, u = open_world(np.array([1.0]), np.array([50.0]), prior=0.0)
    assert u == 0.0 and p[0] == 1.0
    assert open_world(np.zeros(0), np.zeros(0))[1] == 1.0
    with pytest.raises(ValueError):
        open_world(np.array([1.0]), np.array([0.0]), prior=1.0)


def test_each_touch_of_a_session_must_fit():
    """Two touches: a model that fits the first within the noise and misses the second by far is
    unknown's, however well the first fits (as far as the search's miss rate allows); a model that
    fits both leaves unknown less probable than one touch would; the evidence survives its JSON
    form."""
    rng = np.random.default_rng(9)
    noise = rng.normal(0.0, 0.05, 246)
    good = np.abs(noise)
    bad = good + np.concatenate([np.zeros(123), np.full(123, 0.2)])
    limit = 0.05 * np.sqrt(2 / np.pi)
    ev = evidence(["a", "b"], [good, bad], [41] * 6, 0.05, limits=[limit, limit], touches=[3, 3])
    p, u = ev.outcomes()
    assert p[0] > 0.95 and p[1] < 1e-6
    ev_b = evidence(["b"], [bad], [41] * 6, 0.05, limits=[limit, limit], touches=[3, 3])
    assert ev_b.outcomes()[1] >= 1 - SEARCH_MISS and ev_b.outcomes(miss=0.0)[1] > 0.999
    one = evidence(["a"], [good[:123]], [41] * 3, 0.05, limits=[limit])
    both = evidence(["a"], [good], [41] * 6, 0.05, limits=[limit, limit], touches=[3, 3])
    assert both.outcomes()[1] < one.outcomes()[1] / 10          # each touch the pose fits is evidence
    again = type(ev).from_json(ev.to_json())
    assert np.allclose(again.outcomes()[0], p) and again.touches == (3, 3)


def test_touches_of_a_left_out_model_come_back_unknown(small):
    """20 seeded noise-free touches (5 on each of four small meshes of distinct shapes), each
    recognised among the other three: unknown is the most probable outcome on at least 18; among all
    four, the right model is the most probable on at least 19, and unknown stays below 0.05 on
    them."""
    names = [e.name for e in small]
    unknown_top = known_top = low_unknown = 0
    with Recognizer(small) as recognizer:
        for m_index, entry in enumerate(small):
            for i in range(5):
                touch = simulate_random_touch(entry.model, rng=np.random.default_rng((61, m_index, i)),
                                              points=41, spacing=0.3,
                                              angle=60.0, outward=True)
                out = recognizer.recognize(touch, among=[n for n in names if n != entry.name])
                unknown_top += out.unknown > max(out.probabilities.values(), default=0.0)
                assert abs(sum(out.probabilities.values()) + out.unknown - 1.0) < 1e-9
                known = recognizer.recognize(touch)
                known_top += known.best == entry.name and known.confidence > known.unknown
                low_unknown += known.unknown < 0.05
    assert unknown_top >= 18
    assert known_top >= 19 and low_unknown >= 19


def test_similar_scans_are_the_nearest_shapes():
    """The shape signature tells a box (fill 1), a cylinder (pi / 4) and a ball (pi / 6) apart whatever
    their size, and a scan's similar set holds the same shape at another size first."""
    import trimesh

    from tactrec.bench.multi_touch import shape_signature, similar_scans
    from tactrec.recognition import ModelEntry
    from tactrec.surfaces.mesh import MeshModel

    meshes = {"box": trimesh.creation.box(extents=(40.0, 30.0, 20.0)),
              "ball": trimesh.creation.icosphere(subdivisions=3, radius=20.0),
              "can": trimesh.creation.cylinder(radius=15.0, height=50.0, sections=64),
              "big box": trimesh.creation.box(extents=(80.0, 60.0, 40.0)),
              "big can": trimesh.creation.cylinder(radius=30.0, height=100.0, sections=64)}
    entries = [ModelEntry(MeshModel(m.vertices, m.faces, name=n, units="mm"), None) for n, m in meshes.items()]
    fills = [shape_signature(e.model)[0] for e in entries]
    assert abs(fills[0] - 1.0) < 0.01 and abs(fills[1] - np.pi / 6) < 0.05 and abs(fills[2] - np.pi / 4) < 0.02
    assert similar_scans(entries, 0, 2) == [0, 3] and similar_scans(entries, 2, 2) == [2, 4]


def test_a_missed_line_counts_against_the_poses_it_cuts(small, tmp_path):
    """One noisy touch on the capsule (world frame).  A line from 5 mm outside the contact inwards along
    the normal met nothing: it cuts through the capsule's pose, which loses its probability to unknown;
    a line from there outwards changes nothing.  A session file with a missed touch round-trips, and the
    result's JSON counts the missed lines."""
    from tactrec.io.session import MissedLine, SessionMiss, SessionTouch, load_session, save_session

    entry = small[1]
    touch = simulate_random_touch(entry.model, rng=np.random.default_rng((71, 0)), points=41, spacing=0.3, angle=60.0,
                                  noise=0.02, noise_kind="gaussian", outward=False, sensor_frame=False)
    with Recognizer(small) as recognizer:
        session = recognizer.session()
        before = session.add(touch)
        h = before.hypothesis(entry.name)
        assert before.best == entry.name and before.probabilities[entry.name] > 0.9
        on_model = np.asarray(touch.meta["truth"]["contact"], dtype=np.float64)
        contact = (on_model - h.translation) @ h.rotation                      # model -> world
        normal = entry.model.planes(on_model[None])[1][0] @ h.rotation
        away = session.add_miss(MissedLine(contact + 5.0 * normal, normal, 20.0))
        assert away.probabilities[entry.name] == pytest.approx(before.probabilities[entry.name], abs=1e-9)
        cut = session.add_miss(MissedLine(contact + 5.0 * normal, -normal, 20.0))
        assert cut.missed == 2 and cut.probabilities.get(entry.name, 0.0) < 0.2 and cut.unknown > 0.5
    path = tmp_path / "s.json"
    save_session([SessionTouch(touch), SessionMiss(MissedLine(contact + 5.0 * normal, -normal, 20.0))], path)
    loaded = load_session(path)
    assert isinstance(loaded[1], SessionMiss) and np.allclose(loaded[1].line.direction, -normal)
    assert cut.to_json()["missed"] == 2 and "unknown" in cut.to_json()
