"""Touches as a real sensor records them (tactrec.sensor, tactrec simulate's sensor options)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactrec.cli import main
from tactrec.errors import InputError
from tactrec.io.touch import load_touch, save_touch
from tactrec.sensor import Imperfections
from tactrec.simulation import simulate_random_touch
from tactrec.surfaces import load_model

RADIUS = 33.0                                   # the built-in sphere-33, centred at the origin
TOUCH = dict(points=41, spacing=0.3, angle=60.0, sensor_frame=False)


@pytest.fixture(scope="module")
def sphere():
    return load_model("sphere-33")


@pytest.fixture(scope="module")
def mug():
    return load_model("mug")


def _touches(model, imperfections, count=20, seed=0):
    return [simulate_random_touch(model, rng=np.random.default_rng([seed, k]), imperfections=imperfections, **TOUCH)
            for k in range(count)]


def _radial(data):
    return [np.linalg.norm(c, axis=1) - RADIUS for c in data.curves]


def test_a_perfect_sensor_changes_nothing(sphere, mug):
    """Imperfections() gives the same bits as no imperfections, on a closed-form surface and a mesh,
    and a perfect touch is the one this package simulated before it modelled a sensor (seeded
    points of a noisy sphere touch, to 1e-9)."""
    d = simulate_random_touch(sphere, rng=0, points=21, spacing=0.3, noise=0.02, noise_kind="gaussian", contact=True)
    assert np.allclose(d.curves[0][0], [52.273511444717, 88.854420868828, -18.647152337466], atol=1e-9)
    assert np.allclose(d.curves[2][-1], [53.367155741613, 91.014872445293, -20.280374386687], atol=1e-9)
    assert np.allclose(d.contact, [55.01498304158, 89.831850655782, -18.073554108107], atol=1e-9)
    for model in (sphere, mug):
        for k in range(3):
            a = simulate_random_touch(model, rng=k, points=21, spacing=0.3, noise=0.02, noise_kind="gaussian")
            b = simulate_random_touch(model, rng=k, points=21, spacing=0.3, noise=0.02, noise_kind="gaussian",
                                      imperfections=Imperfections())
            assert all(np.array_equal(x, y) for x, y in zip(a.curves, b.curves)) and b.tip_radius == 0


def test_a_round_tip_records_its_centres_at_the_radius(sphere, mug):
    """With a 2 mm tip every point lies 2 mm outside the surface (on the sphere and on the mug, within
    1e-9 and 1e-6), the file carries the radius, and the same seed gives the same touch."""
    for data in _touches(sphere, Imperfections(tip_radius=2.0)):
        assert data.tip_radius == 2.0
        assert all(np.allclose(r, 2.0, atol=1e-9) for r in _radial(data))
    tip = Imperfections(tip_radius=2.0)
    for k in range(5):
        data = simulate_random_touch(mug, rng=k, imperfections=tip, **TOUCH)
        again = simulate_random_touch(mug, rng=k, imperfections=tip, **TOUCH)
        assert all(np.array_equal(x, y) for x, y in zip(data.curves, again.curves))
        distance = mug.planes(data.points)[0]
        assert np.max(np.abs(distance - 2.0)) < 1e-6


def test_a_tip_sweeps_round_convex_edges_and_stays_out_of_tight_hollows():
    """A 3 mm tip on a box (convex edges) and on a torus of radii 4 and 2.5 mm (its hole a hollow of radius
    1.5, tighter than the tip), 20 touches each: every centre lies 3 mm from the mesh by libigl's closest
    points (within 1e-6), so the tip enters the surface nowhere; the steps between centres are
    the surface points' along the path (no chord longer by 0.1%, the median within 1%: a chord across a
    hollow's kink is shorter), and over the box's edges the centres turn in arcs of radius 3:
    no step turns the path by more than the step over the radius allows (plus 1 degree)."""
    import igl
    import trimesh

    from tactrec.surfaces.mesh import MeshModel

    box = trimesh.creation.box(extents=(30.0, 20.0, 12.0)).subdivide().subdivide().subdivide()
    torus = trimesh.creation.torus(major_radius=4.0, minor_radius=2.5, major_sections=96, minor_sections=48)
    tip = Imperfections(tip_radius=3.0)
    hole = []
    for name, mesh in (("box", box), ("torus", torus)):
        model = MeshModel(mesh.vertices, mesh.faces, name=name, units="mm")
        for k in range(20):
            data = simulate_random_touch(model, rng=np.random.default_rng([40, k]), imperfections=tip,
                                         points=31, spacing=0.3, angle=60.0, sensor_frame=False)
            if name == "torus":
                hole.append(np.min(np.linalg.norm(np.concatenate(data.curves)[:, :2], axis=1)))
            points = np.concatenate(data.curves)
            d2, _, _ = igl.point_mesh_squared_distance(points, np.asarray(mesh.vertices, dtype=np.float64),
                                                      np.asarray(mesh.faces, dtype=np.int64))
            distance = np.sqrt(d2)
            assert np.max(np.abs(distance - 3.0)) < 1e-6, (name, k)
            for c in data.curves:
                steps = np.linalg.norm(np.diff(c, axis=0), axis=1)
                assert np.all(steps <= 0.3 * (1 + 1e-3)) and np.median(steps) > 0.3 * 0.99, (name, k, steps.min())
                if name == "box":
                    d = np.diff(c, axis=0)
                    cos = np.sum(d[1:] * d[:-1], axis=1) / (steps[1:] * steps[:-1])
                    turn = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
                    assert np.all(turn <= np.degrees(0.3 / 3.0) + 1.0), (k, turn.max())
    assert min(hole) < 4.0                              # some strokes reach into the torus's hole


def test_uneven_steps_keep_the_curves_length_and_mean_spacing(sphere):
    """Steps between points lie between a and 6a (their mean the spacing, within 10% over 20 touches),
    the longest at least three times the shortest on every curve, each curve spans its perfect
    length within a longest step each side, and every point stays on the surface."""
    steps, length = [], 40 * 0.3
    for data in _touches(sphere, Imperfections(uneven=6.0)):
        for c in data.curves:
            s = np.linalg.norm(np.diff(c, axis=0), axis=1)
            a = 2 * 0.3 / 7
            assert s.min() >= a * (1 - 1e-6) and s.max() <= 6 * a * (1 + 1e-3) and s.max() > 3 * s.min()
            assert abs(s.sum() - length) <= 2 * 6 * a                 # each side short by a step at most
            steps.append(s)
        assert all(np.allclose(r, 0.0, atol=1e-6) for r in _radial(data))
    assert abs(np.mean(np.concatenate(steps)) - 0.3) < 0.03


def test_jitter_and_outliers(sphere):
    """Jitter of 0.02 shows as radial scatter of 0.02 (within 15%, 20 touches); 3% outliers move that
    many points (rounded), each named in the truth and off the surface, while every other point
    stays on it."""
    scatter = np.concatenate([np.concatenate(_radial(d)) for d in _touches(sphere, Imperfections(jitter=0.02))])
    assert abs(np.std(scatter) - 0.02) < 0.003
    for data in _touches(sphere, Imperfections(outliers=0.03)):
        moved = data.meta["truth"]["imperfections"]["outlier_points"]
        assert len(moved) == round(0.03 * sum(len(c) for c in data.curves))
        radial = _radial(data)
        off = np.zeros(len(data.points), dtype=bool)
        bounds = np.cumsum([0] + [len(c) for c in data.curves])
        for i, j in moved:
            off[bounds[i] + j] = True
        r = np.concatenate(radial)
        assert np.all(np.abs(r[off]) > 1e-3) and np.allclose(r[~off], 0.0, atol=1e-9)


def test_strokes_that_miss_the_contact_or_bend(sphere):
    """With ``miss`` 0.3 each curve passes 0.3 from the contact (within 2%) and the curves no longer
    meet; with ``bend`` 0.2 each stroke leaves its best plane by 0.05-0.1 (0.4 bend) at its ends; both stay on
    the surface."""
    from tactrec.io.meeting import closest_on_polyline, find_contact

    for data in _touches(sphere, Imperfections(miss=0.3), count=12):
        contact = np.asarray(data.meta["truth"]["contact"])
        nearest = [np.min(np.linalg.norm(c - contact, axis=1)) for c in data.curves]
        assert np.allclose(nearest, 0.3, rtol=0.02)
        # no point lies on all three: 60 degrees apart, each 0.3 to either side, they miss their
        # least-squares point by at least 0.3 / 3 (the offsets' alternating sum, shared by three)
        meet = find_contact(data.curves)
        assert max(np.linalg.norm(closest_on_polyline(meet[None], c)[0] - meet) for c in data.curves) > 0.09
        assert all(np.allclose(r, 0.0, atol=1e-9) for r in _radial(data))
    for data in _touches(sphere, Imperfections(bend=0.2), count=12):
        for c in data.curves:
            centred = c - c.mean(axis=0)
            normal = np.linalg.svd(centred)[2][2]
            off = np.abs(centred @ normal)
            assert 0.05 < off.max() < 0.1
        assert all(np.allclose(r, 0.0, atol=1e-6) for r in _radial(data))


def test_imperfections_are_validated_and_files_carry_the_tip(tmp_path, sphere):
    """Impossible settings are refused; the tip radius goes through a JSON file and refuses CSV."""
    for bad in (dict(uneven=0.5), dict(outliers=0.6), dict(tip_radius=-1.0), dict(jitter=np.nan),
                dict(outlier_size=(3.0, 0.5))):
        with pytest.raises(ValueError):
            Imperfections(**bad)
    data = _touches(sphere, Imperfections(tip_radius=1.5), count=1)[0]
    save_touch(data, tmp_path / "t.json")
    assert load_touch(tmp_path / "t.json").tip_radius == 1.5
    with pytest.raises(InputError, match="tip_radius"):
        save_touch(data, tmp_path / "t.csv")
    text = json.loads((tmp_path / "t.json").read_text())
    text["tip_radius"] = "big"
    (tmp_path / "bad.json").write_text(json.dumps(text))
    with pytest.raises(InputError, match="tip_radius"):
        load_touch(tmp_path / "bad.json")


def test_simulate_takes_every_sensor_option(tmp_path, capsys):
    """``tactrec simulate`` with every sensor option writes a seeded touch carrying them; a bad value
    is one line and exit status 2 (recognising a round tip's touch: tests/test_tip.py)."""
    args = ["simulate", "sphere-33", "--spacing", "0.3", "--points", "41", "--tip-radius", "1", "--uneven", "4",
            "--jitter", "0.01", "--outliers", "0.02", "--miss", "0.2", "--bend", "0.1", "--seed", "4"]
    assert main(args + ["--out", str(tmp_path / "a.json"), "--quiet"]) == 0
    assert main(args + ["--out", str(tmp_path / "b.json"), "--quiet"]) == 0
    a = json.loads((tmp_path / "a.json").read_text())
    assert a == json.loads((tmp_path / "b.json").read_text())
    assert a["tip_radius"] == 1.0 and a["truth"]["imperfections"]["uneven"] == 4.0
    assert main(["simulate", "sphere-33", "--out", str(tmp_path / "c.json"), "--uneven", "0.5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "uneven" in err[0] and not (tmp_path / "c.json").exists()


def test_a_stream_in_csv_becomes_the_curves(tmp_path, sphere, capsys):
    """Twenty seeded unevenly sampled touches written as a sensor streams them: a ``stroke,t,x,y,z``
    CSV with the rows shuffled, and a ``t,x,y,z`` stream whose strokes are separated by rows
    without coordinates (the sensor lifted); both read back as the touch's curves in time order,
    and the stream is recognised as the file of curves is.  Times that are not numbers, or rows
    with some coordinates missing, are one line naming the file and the line."""
    rng = np.random.default_rng(5)
    for k, data in enumerate(_touches(sphere, Imperfections(uneven=3.0), seed=5)):
        times = [np.sort(rng.uniform(10.0 * i, 10.0 * i + 5.0, len(c))).tolist() for i, c in enumerate(data.curves)]
        rows = [f"{i + 1},{t!r},{x!r},{y!r},{z!r}" for i, c in enumerate(data.curves)
                for t, (x, y, z) in zip(times[i], c.tolist())]
        shuffled = tmp_path / f"strokes-{k}.csv"
        shuffled.write_text("\n".join(["stroke,t,x,y,z"] + list(rng.permutation(rows))) + "\n")
        lifted = tmp_path / f"stream-{k}.csv"
        lines = ["t,x,y,z"]
        for i, c in enumerate(data.curves):
            lines += [f"{t!r},{x!r},{y!r},{z!r}" for t, (x, y, z) in zip(times[i], c.tolist())]
            lines += [f"{times[i][-1] + 1.0!r},,,"]                                   # the lift
        lifted.write_text("\n".join(lines) + "\n")
        for path in (shuffled, lifted):
            back = load_touch(path)
            assert len(back.curves) == len(data.curves)
            assert all(np.array_equal(a, b) for a, b in zip(back.curves, data.curves))
    json_path = tmp_path / "curves.json"
    save_touch(data, json_path)
    outputs = []
    for path in (json_path, lifted):
        assert main(["recognize", str(path), "--models", "sphere-33", "cylinder-50", "--json", "--quiet"]) == 0
        outputs.append(json.loads(capsys.readouterr().out))
    assert outputs[0]["best"] == outputs[1]["best"] == "sphere-33"
    assert outputs[0]["ranking"][0]["error"] == pytest.approx(outputs[1]["ranking"][0]["error"], rel=1e-9, abs=1e-12)
    for bad, where in (("t,x,y,z\n1.0,1,2,3\nsoon,1,2,3\n", "line 3"), ("t,x,y,z\n1.0,1,2,3\n2.0,1,,3\n", "line 3")):
        path = tmp_path / "bad.csv"
        path.write_text(bad)
        assert main(["recognize", str(path), "--models", "sphere-33", "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(path) in err[0] and where in err[0], err


def test_bench_sensor_counts_untraceable_strokes_apart():
    """A stroke no tip can follow is counted apart, not as a miss or a refusal: of four rows (right,
    wrong, refused, untraceable) the summary has 3 touches, 1 right, 1 refused, 1 untraceable."""
    from tactrec.bench.sensor import setting_summary

    base = dict(model="a", seconds=1.0)
    rows = [dict(base, recognized="a", refused=None), dict(base, recognized="b", refused=None),
            dict(base, recognized=None, refused="bad", seconds=None),
            dict(base, recognized=None, refused=None, untraceable="a tip of radius 5 cannot follow", seconds=None)]
    s = setting_summary(rows)
    assert (s["touches"], s["right"], s["refused"], s["untraceable"]) == (3, 1, 1, 1)
    assert s["accuracy_percent"] == pytest.approx(100.0 / 3)
