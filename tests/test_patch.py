"""Touches as patches (tactrec.io.patch, tactrec.estimation_patch, simulate --patch)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactrec.cli import main
from tactrec.errors import InputError
from tactrec.features import Touch
from tactrec.io.touch import load_touch, parse_touch, save_touch
from tactrec.simulation import simulate_patch, simulate_random_touch, truth_pose
from tactrec.surfaces import load_model

from test_bad_input import bad


@pytest.fixture(scope="module")
def sphere():
    return load_model("sphere-33")


@pytest.fixture(scope="module")
def cylinder():
    return load_model("cylinder-50")


def _patches(model, count, seed, **options):
    return [simulate_random_touch(model, rng=np.random.default_rng([seed, k]), maker=simulate_patch, **options)
            for k in range(count)]


def _model_normal(data, g):
    R, _ = truth_pose(data)
    return R @ g.normal


def test_a_patch_gives_the_known_normal_and_curvatures(sphere, cylinder):
    """20 patches of 4 mm on the sphere of radius 33 and on the cylinder of radius 25.2 (random sensor
    frames): noise-free, the normal within 0.05 degrees of the truth and the curvatures within 1% of
    -1/33, -1/33 and 0, -1/25.2; with depth noise of 0.02 mm, within 1 degree, and the curvatures within
    20% of 1/33 (of 1/25.2 for the cylinder's zero), and the noise estimated within 25% of 0.02."""
    for noise in (0.0, 0.02):
        for model, truth in ((sphere, (-1 / 33, -1 / 33)), (cylinder, (0.0, -1 / 25.2))):
            tol = 0.01 * abs(truth[1]) if noise == 0 else 0.2 * abs(truth[1])
            for data in _patches(model, 20, 7, radius=4.0, noise=noise):
                touch = Touch.from_data(data)
                g = touch.estimate
                angle = np.degrees(np.arccos(min(1.0, _model_normal(data, g) @ np.array(data.meta["truth"]["normal"]))))
                assert angle < (0.05 if noise == 0 else 1.0), (model.name, noise, angle)
                assert abs(g.k1 - truth[0]) < tol and abs(g.k2 - truth[1]) < tol, (model.name, noise, g.k1, g.k2)
                if noise:
                    assert abs(touch.noise - noise) < 0.25 * noise, touch.noise


def test_a_patch_is_scored_as_far_as_it_reaches_and_its_rings_read_evenly(sphere):
    """A noise-free 10 mm map of a sphere of radius 33 mm, in a random sensor frame: its rows and
    columns reach farther than its diagonals, and the pose is scored on all of them, while the place
    index reads the sphere's rings (``h / s`` of ``-R (1 - cos(s / R))``, no harmonic) only at the arcs
    every half of every diameter reaches, none beyond."""
    from tactrec.surfaces.mesh_rings import ARCS_MM, touch_rings

    data = simulate_random_touch(sphere, rng=np.random.default_rng(5), maker=simulate_patch, radius=10.0)
    touch = Touch.from_data(data)
    c = touch.geometry.contact
    middles = [int(np.argmin(np.linalg.norm(curve - c, axis=1))) for curve in touch.curves]
    reaches = [float(np.max(np.linalg.norm(half - c, axis=1)))
               for curve, k in zip(touch.curves, middles) for half in (curve[:k + 1], curve[k:])]
    assert max(reaches) > 9.5 and min(reaches) < 9.0, reaches          # rows and columns outreach diagonals
    assert touch.radius > 9.5                                           # every recorded point is scored
    rings = touch_rings(touch, 1)
    even = min(reaches)
    read = np.array([s <= even for s in ARCS_MM])
    assert read[:2].all() and np.isnan(rings[:len(ARCS_MM)][~read]).all(), (even, rings)
    s = np.asarray(ARCS_MM)[read]
    sphere_h = -33.0 * (1.0 - np.cos(s / 33.0)) / s
    assert np.allclose(rings[:len(ARCS_MM)][read], sphere_h, rtol=0.05), (rings, sphere_h)
    assert np.all(np.abs(rings[len(ARCS_MM):][read]) < 0.002), rings


def test_a_patch_file_round_trips_and_reads_as_points(tmp_path, sphere):
    """A simulated height map saved and loaded gives the same points and spokes to the bit; its points
    given as a point patch (with the sphere's outward normals, then without) give the same estimate
    within 1e-3 of the curvature and 0.1 degrees, the normal oriented out either way (the points
    without normals by the convex guess)."""
    data = _patches(sphere, 1, 3, radius=5.0, noise=0.01)[0]
    path = tmp_path / "patch.json"
    save_touch(data, path)
    again = load_touch(path)
    assert again.kind == "patch" and np.array_equal(again.patch.points, data.patch.points)
    assert all(np.array_equal(a, b) for a, b in zip(again.curves, data.curves))
    R, t = truth_pose(data)
    centre = -R.T @ t                                          # the sphere's centre in the data frame
    normals = data.patch.points - centre
    g = Touch.from_data(data).estimate
    for given in (normals.tolist(), None):
        obj = {"units": "mm", "patch": {"points": data.patch.points.tolist()}}
        if given is not None:
            obj["patch"]["normals"] = given
        h = Touch.from_data(parse_touch(obj, "points.json")).estimate
        assert abs(h.k1 - g.k1) < 1e-3 and abs(h.k2 - g.k2) < 1e-3
        assert np.degrees(np.arccos(min(1.0, h.normal @ g.normal))) < 0.1
        assert h.oriented == (given is not None)


def test_a_patch_that_states_its_noise_is_judged_by_it(tmp_path, sphere):
    """A sensor that knows its depth noise states it (``point_sd``, data units): the touch's noise, which
    the fit test and the probabilities read, is then the stated one, in either form of patch and kept
    through a file; a patch that states none is judged by its own estimate."""
    data = _patches(sphere, 1, 5, radius=5.0, noise=0.02)[0]
    own = Touch.from_data(data).noise
    assert own > 0.0
    obj = json.loads(json.dumps(data.to_json()))
    for form in ("height", "points"):
        if form == "points":
            obj["patch"] = {"points": data.patch.points.tolist()}
        obj["patch"]["point_sd"] = 0.02
        path = tmp_path / f"{form}.json"
        path.write_text(json.dumps(obj))
        stated = load_touch(path)
        assert Touch.from_data(stated).noise == 0.02
        save_touch(stated, tmp_path / "again.json")
        assert Touch.from_data(load_touch(tmp_path / "again.json")).noise == 0.02


def test_bad_patches_get_one_line(tmp_path, capsys):
    """A map mostly null, a patch of a few points, a hole around the middle, a patch beside curves, a patch
    with a contact, a sensor pose that is no rotation, and a stated noise that is negative or no number:
    each one line naming the file, exit status 2."""
    big = [[0.0] * 9 for _ in range(9)]
    holed = [[None if (i + j) % 3 else 0.0 for j in range(9)] for i in range(9)]
    middle = [[None if abs(i - 4) <= 1 and abs(j - 4) <= 1 else 0.01 * (i * i + j * j) for j in range(9)]
              for i in range(9)]
    cases = [({"patch": {"height": holed, "pitch": 0.5}}, "null"),
             ({"patch": {"points": [[i, i * i, 0] for i in range(8)]}}, "at least 20"),
             ({"patch": {"height": middle, "pitch": 0.5}}, "too holed"),
             ({"patch": {"height": big, "pitch": 0.5}, "curves": [[[0, 0, 0]]]}, "one of"),
             ({"patch": {"height": big, "pitch": 0.5}, "contact": [0, 0, 0]}, "no 'contact'"),
             ({"patch": {"height": big, "pitch": 0.5, "sensor": {"rotation": [[2, 0, 0], [0, 1, 0], [0, 0, 1]],
                                                                  "translation": [0, 0, 0]}}}, "rotation"),
             ({"patch": {"height": big, "pitch": 0.5, "point_sd": -0.1}}, "point_sd"),
             ({"patch": {"height": big, "pitch": 0.5, "point_sd": "0.1"}}, "point_sd")]
    for k, (obj, problem) in enumerate(cases):
        path = tmp_path / f"bad{k}.json"
        path.write_text(json.dumps(obj))
        with pytest.raises(InputError, match=problem):
            load_touch(path)
    bad(capsys, ["simulate", "sphere-33", "--out", tmp_path / "x.json", "--pitch", "0.1"], "tactrec simulate",
        "--patch")


def test_a_simulated_ray_stops_at_the_surface_not_at_a_sign_far_from_it():
    """A ray down onto the plane z = 0 of a model whose signed distance flips sign for a moment 5 mm above
    it (as a mesh's does far from it, signed by the nearest face beside a concave edge): the pixel's
    depth is the plane's, 10 mm, not the flip's."""
    from tactrec.simulation import _first_hits

    class Plane:
        def planes(self, x):
            z = np.asarray(x)[..., 2]
            flip = (z > 4.9) & (z < 5.05)
            return np.where(flip, -z, z), None

    origins = np.array([[0.0, 0.0, 10.0], [1.0, 2.0, 10.0]])
    depth = _first_hits(Plane(), origins, np.array([0.0, 0.0, -1.0]), 12.0, 0.1)
    assert np.allclose(depth, 10.0, atol=1e-6), depth


def test_simulate_patch_writes_a_height_map(tmp_path, capsys):
    """``simulate --patch 3`` writes a height map of about 400 pixels that ``load_touch`` reads; ``--blur``
    smooths the surface the gel sees (the map moves, but by less than the sag it smooths: 0.05 mm on
    this sphere), ``--depth`` leaves out the pixels below it, ``--state-noise`` writes the depth noise
    into the map."""
    maps = {}
    for name, extra in (("plain", []), ("blur", ["--blur", "0.5"]), ("depth", ["--depth", "0.1"])):
        out = tmp_path / f"{name}.json"
        assert main(["simulate", "sphere-33", "--patch", "3", "--out", str(out), "--seed", "1", *extra]) == 0
        obj = json.loads(out.read_text())
        assert set(obj["patch"]) == {"height", "pitch", "sensor"}
        maps[name] = np.array(obj["patch"]["height"], dtype=float)
        load_touch(out)
    assert 370 <= np.isfinite(maps["plain"]).sum() <= 430
    moved = np.nanmax(np.abs(maps["blur"] - maps["plain"]))
    assert 1e-4 < moved < 0.05, moved
    assert np.nanmax(maps["depth"]) <= 0.1 and np.isfinite(maps["depth"]).sum() < np.isfinite(maps["plain"]).sum()
    out = tmp_path / "stated.json"
    assert main(["simulate", "sphere-33", "--patch", "3", "--noise", "0.02", "--state-noise", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["patch"]["point_sd"] == 0.02 and Touch.from_data(load_touch(out)).noise == 0.02
    capsys.readouterr()


def test_patches_are_recognised(small):
    """24 patches of 6 mm (about 400 points, depth noise 0.02 mm) at random places on the four small
    meshes, in random sensor frames: at least 22 right."""
    from tactrec.recognition import Recognizer

    with Recognizer(small) as r:
        right = sum(r.recognize(simulate_random_touch(small[k % 4].model, rng=np.random.default_rng([11, k]),
                                                      maker=simulate_patch, radius=6.0, noise=0.02)).best
                    == small[k % 4].name for k in range(24))
    assert right >= 22, right


def test_patches_are_located(table1):
    """20 noise-free patches (radius a tenth of the surface's size) on the four surfaces of Table 1:
    every one right, sure (probability >= 0.95), and its middle, under the found pose, within 1e-6 of
    the size of the true point, up to the surface's symmetries."""
    from tactrec.recognition import Recognizer

    surfaces = table1.entries
    with Recognizer(surfaces) as r:
        for k in range(20):
            model = surfaces[k % 4].model
            data = simulate_random_touch(model, rng=np.random.default_rng([12, k]), maker=simulate_patch,
                                         radius=0.1 * model.size)
            result = r.recognize(data)
            assert result.best == model.name and result.confidence >= 0.95, (model.name, k, result.best)
            reg = result.registration
            found = reg.scale * (reg.rotation @ data.contact) + reg.translation
            error = model.location_error(found, data.meta["truth"]["contact"])
            assert error is not None and error < 1e-6 * model.size, (model.name, k, error)


def test_a_patch_that_fits_another_place_as_well_is_not_said_located():
    """20 seeded 6 mm patches (noise 0.02 mm) of the banana: recognised with the banana alone, every
    answer that says it is located puts the patch's middle within 1 mm of where it was taken (a
    smooth patch fits other places of a smooth scan within the noise, and such an answer says it
    cannot tell them apart: ``place`` below 0.95), and at least two say so; on one mesh of two
    bananas 300 mm apart, whose places come in pairs alike, at least 18 say they are not located."""
    from tactrec.database import build_entries
    from tactrec.recognition import ModelEntry, Recognizer
    from tactrec.surfaces.mesh import MeshModel
    from tactrec.tables import CurvatureTable

    banana = build_entries(["banana"]).entries
    V, F = banana[0].model.vertices, banana[0].model.faces
    twins = MeshModel(np.vstack([V, V + [300.0, 0.0, 0.0]]), np.vstack([F, F + len(V)]), name="twins", units="mm")
    located = far = twinned = 0
    with Recognizer(banana) as one, Recognizer([ModelEntry(twins, CurvatureTable(twins.table_samples()))]) as two:
        for k in range(20):
            data = simulate_random_touch(banana[0].model, rng=np.random.default_rng([23, k]), maker=simulate_patch,
                                         radius=6.0, noise=0.02)
            result = one.recognize(data)
            reg = result.registration
            off = np.linalg.norm(reg.scale * (reg.rotation @ data.contact) + reg.translation
                                 - np.asarray(data.meta["truth"]["contact"]))
            located += result.located
            far += result.located and off > 1.0
            assert result.located == (json.loads(json.dumps(result.to_json()))["located"])
            twinned += not two.recognize(data).located
    assert far == 0 and located >= 2, (far, located)
    assert twinned >= 18, twinned


def test_a_session_mixes_patches_and_curves_and_serve_reads_them(small):
    """A session on the egg (its pose in the world seeded): a curve touch, then a 4 mm patch, each in
    its own sensor frame with ``sensor2world``, added through ``serve``'s requests: the egg after
    each, surer after the patch than after the curves alone; a ``recognize`` request of the patch
    answers what the Python call gives."""
    from tactrec.io.touch import parse_touch
    from tactrec.recognition import Recognizer
    from tactrec.service import Service
    from tactrec.simulation import random_rigid_motion, sensor_to_world

    egg = small[0]
    pose = random_rigid_motion(np.random.default_rng(5), extent=200.0)
    curve = simulate_random_touch(egg.model, rng=np.random.default_rng([5, 1]), points=21, spacing=0.3,
                                  noise=0.02, noise_kind="gaussian")
    patch = simulate_random_touch(egg.model, rng=np.random.default_rng([5, 2]), maker=simulate_patch, radius=4.0,
                                  noise=0.02)
    with Recognizer(small) as recognizer:
        service = Service(recognizer, seed=1)
        direct = recognizer.recognize(parse_touch(patch.to_json(), "x")).to_json()
        served = service.answer(json.dumps({"id": 1, "recognize": patch.to_json()}))
        assert served["best"] == direct["best"] == "egg"
        assert served["confidence"] == pytest.approx(direct["confidence"], abs=1e-12)
        answers = []
        for k, data in enumerate((curve, patch)):
            R, t = sensor_to_world(data, pose)
            request = dict(data.to_json(), sensor2world={"rotation": R.tolist(), "translation": t.tolist()})
            answers.append(service.answer(json.dumps({"id": k, "session": "s", "add": request})))
    assert [a["best"] for a in answers] == ["egg", "egg"], answers
    assert answers[1]["confidence"] >= answers[0]["confidence"]
