"""Touches recorded by a round tip: the centres, on the surface offset by its radius (tactrec.tip)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactrec.cli import main
from tactrec.errors import InputError
from tactrec.features import Touch
from tactrec.io.touch import TactileData, save_touch
from tactrec.probability import fit_limit
from tactrec.recognition import ModelEntry, Recognizer
from tactrec.sensor import Imperfections
from tactrec.simulation import simulate_random_touch
from tactrec.surfaces import load_model
from tactrec.tables import CurvatureTable
from tactrec.tip import Offset, corrected, foot_distance


RADIUS = 33.0                                   # the built-in sphere-33, centred at the origin
TOUCH = dict(points=41, spacing=0.3, angle=60.0)


@pytest.fixture(scope="module")
def closed():
    return [ModelEntry(m, CurvatureTable(m.table_samples())) for m in map(load_model, ("sphere-33", "cylinder-50"))]


def _tip_touch(model, r, *seed, **options):
    return simulate_random_touch(model, rng=np.random.default_rng(list(seed)), imperfections=Imperfections(tip_radius=r),
                                 **(TOUCH | options))


@pytest.mark.parametrize("r", [1.0, 2.0, 5.0])
def test_a_sphere_touched_with_a_tip_gives_its_own_curvature(r):
    """On the sphere of radius 33, 20 touches with a tip of radius r: the centres bend as a sphere of
    33 + r, and the corrected estimate gives -1/33 (within 1%; uncorrected it would be off by
    r / (33 + r), 3% at r = 1), its contact on the sphere (within 0.05 mm) and the estimate of each
    side tried corrected."""
    sphere = load_model("sphere-33")
    for k in range(20):
        data = _tip_touch(sphere, r, 3, k, sensor_frame=False, outward=bool(k % 2))
        touch = Touch.from_data(data)
        assert touch.tip == r
        g = touch.estimate
        assert abs(g.k1 * RADIUS + 1.0) < 0.01 and abs(g.k2 * RADIUS + 1.0) < 0.01
        assert abs(np.linalg.norm(g.contact) - RADIUS) < 0.05
        for sign, side in touch.sides:
            raw = touch.estimate if sign == 1 else touch.estimate.flipped()
            assert np.allclose(side.normal, raw.normal) and side.k1 >= side.k2
        # the points moved onto the surface on the outward side lie on the sphere (the local fit's normals)
        surface = touch.on_surface(1 if np.dot(g.normal, g.contact) > 0 else -1).points
        assert np.max(np.abs(np.linalg.norm(surface, axis=1) - RADIUS)) < 0.02


def test_the_correction_gives_the_surface_under_the_tip():
    """The centres of a 2 mm tip trace radii 10 and -5 (curvatures 0.1 and -0.2): the surface under them
    has radii 12 and -3 (each the centres' radius plus the tip's, signed), the contact 2 below the
    centre; where the centres bend at the tip's radius or tighter (over a sharp edge) the surface
    reads as bending more tightly than the tip, never as flat or the other way."""
    from tactrec.estimation import LocalGeometry

    g = LocalGeometry(np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.1, -0.2, np.eye(3)[:2], np.eye(3)[:2],
                      np.array([0.1, -0.2]), True)
    c = corrected(g, 2.0)
    assert np.isclose(1.0 / c.k1, 12.0) and np.isclose(1.0 / c.k2, -3.0)
    assert np.allclose(c.contact, [0.0, 0.0, -2.0]) and np.allclose(c.normal_curvatures, [c.k1, c.k2])
    for r in (5.0, 5.5, 7.0):                      # an edge: the surface bends tighter than the tip there
        k2 = corrected(g, r).k2
        assert k2 < 0 and -1.0 / k2 < r


def test_a_bend_is_judged_over_the_curves_length():
    """A circular arc's bend is its curvature, never tighter (great circles of a ball of 3 mm, 0.8 rad
    either side: within 5% of -1/3); the centres of a tip
    rounding a sharp edge (two straight pieces joined by an arc of the tip's radius) bend far more
    gently over the curve than at the kink, so a tip of that radius traces them."""
    from tactrec.estimation import estimate
    from tactrec.tip import bends, traceable

    ball = _ball_touch(3.0, 5.0, outward=True)
    g = estimate(ball)
    b = bends(ball.curves, g)
    assert np.all(b >= -1.0 / 3.0) and np.all(b < -0.95 / 3.0)
    assert not traceable(ball.curves, g, 5.0) and traceable(ball.curves, g, 2.0)
    r, curves = 2.0, []
    for a in np.deg2rad([0.0, 60.0, 120.0]):             # a roof ridge along y, its faces at 45 degrees
        u = np.array([np.cos(a), np.sin(a), 0.0])
        s = np.linspace(-12.0, 12.0, 49)
        across = s * u[0]                               # across the ridge
        along = s * u[1]
        # the tip's centre over a ridge with faces z = -|x|: an arc of radius r above it, then lines
        h = np.where(np.abs(across) <= r / np.sqrt(2.0), np.sqrt(np.maximum(r * r - across ** 2, 0.0)),
                     r * np.sqrt(2.0) - np.abs(across))
        curves.append(np.stack([across, along, h], axis=1))
    data = TactileData.from_arrays(curves, outward=[0.0, 0.0, 1.0], contact=[0.0, 0.0, r], units="mm",
                                   source="ridge.json", tip_radius=r)
    g = estimate(data)
    assert traceable(data.curves, g, r)
    assert Touch.from_data(data).tip == r


def test_the_offset_of_a_closed_form_surface_is_measured_to_the_foot_point():
    """Centres a tip of 5 records on the cylinder-50 and the sphere-33 lie on the offset of the implicit
    surface to 1e-6 by :class:`Offset`, where the first-order distance f / |grad f| minus r is off
    by a tenth of a millimetre or more."""
    for name in ("sphere-33", "cylinder-50"):
        model = load_model(name)
        x = _tip_touch(model, 5.0, 4, sensor_frame=False).points
        assert np.max(np.abs(Offset(model, 5.0).planes(x)[0])) < 1e-6
        assert np.max(np.abs(model.planes(x)[0] - 5.0)) > 0.1
        d, n = foot_distance(model, x)
        assert np.allclose(np.linalg.norm(n, axis=1), 1.0) and np.allclose(d, 5.0, atol=1e-6)


@pytest.mark.parametrize("r", [1.0, 2.0, 5.0])
def test_small_meshes_touched_with_a_tip_are_recognised(small, r):
    """Six seeded touches of each of the four small meshes (24) with a tip of radius r, in random
    sensor frames: at least 22 recognised, and at least 22 right with an error, measured from the
    centres against the model offset by r under its pose, that is a fit (within twice the touch's
    fit limit); each such one's contact on the smooth meshes lands on the model (within 0.05 mm), not
    at the tip's centre r off it
    (across the brick's sharp edges the centres turn at the tip's radius, and the data normal, which
    moves the contact, is a few degrees off)."""
    right = fitted = 0
    with Recognizer(small) as recognizer:
        for m, entry in enumerate(small):
            for k in range(6):
                data = _tip_touch(entry.model, r, 21, m, k)
                result = recognizer.recognize(data)
                if result.best != entry.name:
                    continue
                right += 1
                reg, touch = result.registration, result.touch
                moved = touch.points @ reg.rotation.T + reg.translation          # the points kept (tactrec.outliers)
                offset_error = float(np.mean(np.abs(entry.model.planes(moved)[0] - r)))
                assert np.isclose(offset_error, reg.error, rtol=1e-6, atol=1e-12)
                if offset_error > 2.0 * fit_limit(touch, recognizer.floor):
                    continue                                       # the right model, its pose not found
                fitted += 1
                contact = reg.rotation @ result.estimate.contact + reg.translation
                assert entry.name == "brick" or entry.model.distance(contact[None])[0] < 0.05
    assert right >= 22 and fitted >= 22


def test_closed_forms_and_the_paper_method_take_a_tip(closed):
    """fast and paper recognise 20 touches of the sphere-33 with a 2 mm tip among the sphere and the
    cylinder-50 (at least 18 each); fast's errors, against the offset, are within the fit limit."""
    sphere = closed[0].model
    touches = [_tip_touch(sphere, 2.0, 6, k) for k in range(20)]
    with Recognizer(closed) as fast, Recognizer(closed, method="paper") as paper:
        results = [fast.recognize(d) for d in touches]
        assert sum(r.best == "sphere-33" for r in results) >= 18
        assert all(r.registration.error <= 2.0 * fit_limit(r.touch, fast.floor) for r in results
                   if r.best == "sphere-33")
        assert sum(paper.recognize(d).best == "sphere-33" for d in touches) >= 18


def test_a_session_mixes_tip_radii(small):
    """On each small mesh, touches with tips of 0, 2 and 5 mm in one session: the right model, no touch
    slipped, every touch consistent with the joint pose, which fits each against its own offset
    (joint error below 1e-3 mm); measured against the plain model the 5 mm touch is 5 mm off."""
    with Recognizer(small) as recognizer:
        for m, entry in enumerate(small):
            session = recognizer.session()
            for k, r in enumerate((0.0, 2.0, 5.0)):
                data = _tip_touch(entry.model, r, 5, m, k, sensor_frame=False)
                result = session.add(data)
            best = result.ranking[0]
            assert best.model == entry.name and result.slipped == () and all(best.consistent)
            assert best.error < 1e-3
            moved = data.points @ best.rotation.T + best.translation
            assert abs(np.median(entry.model.planes(moved)[0]) - 5.0) < 0.01


def test_recognize_a_tip_file_end_to_end(tmp_path, capsys):
    """``tactrec simulate --tip-radius 2`` then ``tactrec recognize --json``: the sphere, its curvatures
    those of the sphere of 33 (not of the centres' 35)."""
    out = tmp_path / "t.json"
    assert main(["simulate", "sphere-33", "--out", str(out), "--spacing", "0.3", "--points", "41",
                 "--tip-radius", "2", "--seed", "3", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["recognize", str(out), "--models", "sphere-33", "cylinder-50", "--json"]) == 0
    found = json.loads(capsys.readouterr().out.strip().splitlines()[0])
    assert found["best"] == "sphere-33"
    assert np.allclose(found["curvatures"], -1.0 / RADIUS, rtol=0.01)


def _ball_touch(radius, tip, outward):
    """Three great circles of a ball of ``radius`` through its top, 60 degrees apart, with ``tip``."""
    s = np.linspace(-0.8, 0.8, 41)
    curves = []
    for a in np.deg2rad([0.0, 60.0, 120.0]):
        u = np.array([np.cos(a), np.sin(a), 0.0])
        curves.append(radius * (np.sin(s)[:, None] * u + np.cos(s)[:, None] * np.array([0.0, 0.0, 1.0])))
    return TactileData.from_arrays(curves, outward=[0.0, 0.0, 1.0] if outward else None, units="mm",
                                   source="tight.json", tip_radius=tip)


def test_a_bend_tighter_than_the_tip_is_one_line(tmp_path, capsys):
    """Centres bending as a ball of 3 mm with a 5 mm tip and the outward side given: no surface could
    give them (it would be concave more tightly than the tip); an InputError naming the file, and
    ``tactrec recognize`` says so in one line with exit status 2.  Without ``outward`` the other side
    (a concave bowl of 8 mm) is tried alone."""
    with pytest.raises(InputError, match="tip_radius 5.*tight.json|tight.json.*tip_radius 5"):
        Touch.from_data(_ball_touch(3.0, 5.0, outward=True))
    touch = Touch.from_data(_ball_touch(3.0, 5.0, outward=False))
    assert [sign for sign, _ in touch.sides] == [-1]
    assert np.allclose(touch.oriented(-1).k1, 1.0 / 8.0, rtol=0.01)
    save_touch(_ball_touch(3.0, 5.0, outward=True), tmp_path / "tight.json")
    assert main(["recognize", str(tmp_path / "tight.json"), "--models", "sphere-33"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tip_radius" in err[0] and "tight.json" in err[0]
