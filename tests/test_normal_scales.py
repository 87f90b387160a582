"""The data normal at several scales (tactrec.normal_scales): the first millimetre sees a sharp place."""

import numpy as np
from tactrec.features import Touch
from tactrec.simulation import random_rigid_motion


def _angle(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def _sphere_touch(seed: int, radius: float = 20.0, length: float = 12.0, spacing: float = 0.3):
    """Three planar curves through the top of a sphere, in planes 60 degrees apart, in a random frame."""
    rng = np.random.default_rng(seed)
    s = np.arange(-length, length + 1e-9, spacing) / radius
    curves = []
    for phi in np.deg2rad([0.0, 60.0, 120.0]) + rng.uniform(0, np.pi):
        d = np.array([np.cos(phi), np.sin(phi), 0.0])
        curves.append(radius * (np.sin(s)[:, None] * d + (np.cos(s)[:, None] - 1.0) * np.array([0, 0, 1.0])))
    R, t = random_rigid_motion(rng, extent=50.0)
    from tactrec.io.touch import TactileData

    data = TactileData.from_arrays([c @ R.T + t for c in curves], outward=R @ np.array([0, 0, 1.0]), units="mm")
    return Touch.from_data(data), R @ np.array([0, 0, 1.0])


def test_every_scale_gives_a_sphere_s_normal_and_they_agree():
    for seed in range(20):
        touch, normal = _sphere_touch(seed)
        scales = touch.scales
        assert len(scales.normals) >= 4, seed
        assert max(_angle(n, normal) for n in scales.normals) < 1.0, seed
        assert scales.agree, seed


def _cone_touch(seed: int, bend: float = 40.0, tip: float = 1.5, length: float = 12.0, spacing: float = 0.3):
    """Three planar curves through the apex of a right circular cone (half-angle 45 degrees), each
    down one generator and up another ``180 - bend`` degrees round, in a random frame.  Beyond
    ``tip`` mm from the apex each curve's first half turns 60 degrees further down in its plane, as
    a thin part's surface folds away: the window sees the fold, the first millimetre the cone."""
    rng = np.random.default_rng(seed)
    s = np.arange(spacing, length + 1e-9, spacing)
    curves = []
    for theta in np.deg2rad([0.0, 60.0, 120.0]) + rng.uniform(0, np.pi):
        a, b = (np.array([np.cos(x), np.sin(x), -1.0]) / np.sqrt(2.0) for x in (theta, theta + np.pi - np.deg2rad(bend)))
        across = (b - (b @ a) * a) / np.linalg.norm(b - (b @ a) * a)          # in the curve's plane, towards b
        turned = np.cos(np.pi / 3) * a - np.sin(np.pi / 3) * across            # 60 degrees further from b
        first = np.where(s[:, None] <= tip, s[:, None] * a, tip * a + (s[:, None] - tip) * turned)
        curves.append(np.concatenate([first[::-1], np.zeros((1, 3)), s[:, None] * b]))
    R, t = random_rigid_motion(rng, extent=50.0)
    from tactrec.io.touch import TactileData

    data = TactileData.from_arrays([c @ R.T + t for c in curves], contact=t, outward=R @ np.array([0, 0, 1.0]),
                                   units="mm")
    return Touch.from_data(data), R @ np.array([0, 0, 1.0])


def test_the_finest_scale_finds_a_cone_s_axis_where_the_window_does_not():
    """At a cone's apex each curve is two generators: bent sideways (planes that do not hold the
    axis), their window fit tilts the normal; the first chords lie on the cone, their tips on a
    circle about its axis.  The scales then disagree: the touch says it is on a sharp place."""
    off = []
    for seed in range(20):
        touch, axis = _cone_touch(seed)
        off.append((_angle(touch.scales.normals[0], axis), _angle(touch.geometry.normal, axis),
                    touch.scales.agree))
    fine, window, agree = np.array(off).T
    assert np.max(fine) < 0.5, fine
    assert np.min(window) > 10.0, window
    assert not np.any(agree)
