"""Imperfect traces (tactrec.io.meeting, recognition): curves that pass near each other, the meeting
point reported, one-sided curves and four to six curves."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from tactrec.cli import main
from tactrec.errors import InputError
from tactrec.io.meeting import MEETING, check_meeting, meeting
from tactrec.io.touch import save_touch
from tactrec.recognition import Recognizer
from tactrec.sensor import Imperfections
from tactrec.simulation import simulate_random_touch, truth_contact


def _touch(model, *seed, curves=3, imperfections=None, noise=0.01):
    return simulate_random_touch(model, rng=np.random.default_rng(list(seed)), noise=noise, noise_kind="gaussian",
                                 points=31, spacing=0.3, angle=180.0 / curves, curves=curves,
                                 imperfections=imperfections)


def test_curves_that_miss_each_other_meet_at_their_least_squares_point(small):
    """20 touches of the small meshes whose curves each pass 0.3 mm from the contact (``miss``), with no
    contact given: the meeting point lies within 0.6 mm of the true contact, the curves' squared
    distances from it sum to no more than from the truth (3 x 0.3^2, within 2%), the result reports the
    largest as ``meeting`` (of the 0.3 mm miss's order: over 0.03, at most the three misses in one) and
    the right model wins in 18 or more.
    The same touches traced through one point report a meeting of 0 (under 1e-9 mm)."""
    right = 0
    with Recognizer(small) as recognizer:
        for k in range(20):
            entry = small[k % len(small)]
            data = _touch(entry.model, 21, k, imperfections=Imperfections(miss=0.3), noise=0.0)
            point, gaps = meeting(data)
            truth = truth_contact(data)
            assert np.linalg.norm(point - truth) < 0.6
            assert np.sum(gaps ** 2) <= 3 * 0.3 ** 2 * 1.02             # least squares: no worse than the truth
            result = recognizer.recognize(data)
            assert 0.03 < result.meeting <= 0.3 * np.sqrt(3) * 1.02 and result.to_json()["meeting"] == result.meeting
            right += result.best == entry.name
            clean = _touch(entry.model, 21, k, noise=0.0)
            assert recognizer.recognize(clean).meeting < 1e-9
    assert right >= 18


def test_curves_farther_apart_than_the_tolerance_do_not_meet(small, tmp_path, capsys):
    """A curve moved off the others by 6 median spacings, along the normal: one line naming the file
    and the tolerance, exit status 2; moved by 2 spacings, the curves meet."""
    data = _touch(small[0].model, 22, 0, noise=0.0)
    normal = np.asarray(data.outward) / np.linalg.norm(data.outward)
    for factor, ok in ((2.0, True), (6.0, False)):
        shift = factor * data.spacing * normal
        moved = dataclasses.replace(data, curves=(data.curves[0], data.curves[1] + shift, data.curves[2]))
        if ok:
            assert check_meeting(moved) is not None
            continue
        with pytest.raises(InputError, match="do not meet"):
            check_meeting(moved)
        path = tmp_path / "apart.json"
        save_touch(moved, path)
        import trimesh

        model = tmp_path / "egg.obj"
        trimesh.Trimesh(small[0].model.vertices, small[0].model.faces).export(model)
        assert main(["recognize", str(path), "--models", str(model), "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(path) in err[0] and f"{MEETING} point spacings" in err[0]


def test_one_sided_curves(small):
    """20 touches whose curves each start or end at the contact (half of each section, to a seeded
    side), noise 0.01 mm: the right model in 18 or more, with the contact within 0.05 mm of the truth."""
    right = 0
    with Recognizer(small) as recognizer:
        for k in range(20):
            entry = small[k % len(small)]
            data = _touch(entry.model, 23, k)
            rng = np.random.default_rng([23, k])
            middle = len(data.curves[0]) // 2
            halves = tuple(np.asarray(c)[middle:] if rng.random() < 0.5 else np.asarray(c)[:middle + 1]
                           for c in data.curves)
            result = recognizer.recognize(dataclasses.replace(data, curves=halves))
            truth = truth_contact(data)
            near = np.linalg.norm(result.estimate.contact - truth) < 0.05
            right += result.best == entry.name and near
    assert right >= 18


@pytest.mark.parametrize("curves", [4, 5, 6])
def test_four_to_six_curves(small, curves):
    """12 touches of 4, 5 and 6 curves (180 / n degrees apart), noise 0.01 mm: the right model in 11 or
    more, and the JSON result lists the touch's contact."""
    right = 0
    with Recognizer(small) as recognizer:
        for k in range(12):
            entry = small[k % len(small)]
            result = recognizer.recognize(_touch(entry.model, 24, curves, k, curves=curves))
            right += result.best == entry.name
            assert len(json.loads(json.dumps(result.to_json()))["contact"]) == 3
    assert right >= 11


def _u_curve(direction: np.ndarray, shift: float, depth: float = 3.0) -> np.ndarray:
    """A section of a 3 mm plate through the origin along ``direction`` (in the x-y plane), moved
    ``shift`` across it: along the top face (z = 0) to 10 mm, round the plate's edge and back along
    the bottom face (z = -depth), 0.3 mm steps."""
    across = np.array([-direction[1], direction[0], 0.0])
    s = np.arange(-6.0, 10.0 + 1e-9, 0.3)
    top = s[:, None] * direction + shift * across
    down = 10.0 * direction + shift * across + np.linspace(0, -depth, 11)[1:-1, None] * np.array([0, 0, 1.0])
    bottom = s[::-1, None] * direction + shift * across + np.array([0.0, 0.0, -depth])
    return np.concatenate([top, down, bottom])


def test_every_point_the_curves_meet_at_is_found():
    """Three sections of a plate, 60 degrees apart, that meet on its top face and again on its bottom
    face 3 mm below: ``meeting_points`` finds both, :func:`find_contact`'s first.  Where the strokes
    on the top face miss each other by 0.2 mm and the bottom ones do not (a far meeting closer than
    the one traced), both are still found, so a recognition can try the traced one."""
    from tactrec.io.meeting import find_contact, meeting_points

    dirs = [np.array([np.cos(a), np.sin(a), 0.0]) for a in np.deg2rad([0.0, 60.0, 120.0])]
    exact = [_u_curve(d, 0.0) for d in dirs]
    points = meeting_points(exact, MEETING * 0.3)
    assert len(points) == 2
    np.testing.assert_allclose(points[0], find_contact(exact))
    assert sorted(round(float(p[2]), 6) for p in points) == [-3.0, 0.0]
    for p in points:
        assert np.hypot(p[0], p[1]) < 1e-9
    missed = []
    for d, shift in zip(dirs, (0.2, 0.2, 0.2)):
        c = _u_curve(d, 0.0)
        top = c[:, 2] > -1.5
        c[top] += shift * np.array([-d[1], d[0], 0.0])
        missed.append(c)
    points = meeting_points(missed, MEETING * 0.3)
    assert len(points) == 2 and abs(points[0][2] + 3.0) < 1e-6       # the far, exact meeting first
    assert abs(points[1][2]) < 1e-6 and np.hypot(points[1][0], points[1][1]) < 0.3


def test_only_curves_that_miss_each_other_are_tried_at_other_meeting_points(small):
    """The recognizer looks for other meeting points only where the curves miss each other beyond
    their noise: 10 touches each of the small meshes at noise 0 and 0.05 mm pass through one point
    (never missing), and the same touches with each curve 0.3 mm off the contact (``miss``) all miss."""
    from tactrec.features import Touch
    from tactrec.recognition.again import missing as _missing

    for k in range(10):
        entry = small[k % len(small)]
        for noise in (0.0, 0.05):
            assert not _missing(Touch.from_data(_touch(entry.model, 25, k, noise=noise)))
        assert _missing(Touch.from_data(_touch(entry.model, 25, k, imperfections=Imperfections(miss=0.3), noise=0.0)))
