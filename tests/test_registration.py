"""Paper registration on closed-form surfaces (Section 4.2): gradient, pose, location."""

import numpy as np
import pytest

from tactrec.estimation import estimate
from tactrec.registration import closedform_paper
from tactrec.registration.result import local_frame
from tactrec.simulation import simulate_touch
from tactrec.surfaces import load_model
from tactrec.tables import CurvatureTable


def test_analytic_gradient_of_eq11_matches_finite_differences():
    m = load_model("ellipsoid")
    touch = simulate_touch(m, (0.8, 1.0), points=31, spacing=0.02, noise=0.001, rng=0)
    geom = estimate(touch)
    local = (touch.points - geom.contact) @ local_frame(geom.normal, geom.directions[0]).T
    problem = closedform_paper.Superposition(m, local)
    uv = np.array([[0.83, 1.04], [2.0, 0.5]])
    phi = np.array([0.4, 2.0])
    E, G, _ = problem.energy_grad(uv, phi)
    h = 1e-6
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        plus = problem.energy(uv + step[:2], phi + step[2])
        minus = problem.energy(uv - step[:2], phi - step[2])
        assert np.allclose(G[:, k], (plus - minus) / (2 * h), rtol=1e-4, atol=1e-7)
    assert np.allclose(E, problem.energy(uv, phi))


@pytest.mark.parametrize("name, uv", [("crossed-trough", (0.35, -0.2)), ("monkey-saddle", (0.1, 0.3)),
                                      ("elliptic-paraboloid", (1.21, 0.43))])
def test_registration_recovers_the_pose_from_the_sensor_frame(name, uv):
    m = load_model(name)
    table = CurvatureTable(m.table_samples())
    touch = simulate_touch(m, uv, points=61, spacing=0.02, noise=0.0, rng=7)
    truth = touch.meta["truth"]
    reg = closedform_paper.register(m, table, estimate(touch), touch.points)
    assert reg.ok and reg.error < 1e-4
    assert m.location_error(reg.location, truth["contact"]) < 5e-3
    # the recovered pose maps the data onto the surface ...
    mapped = touch.points @ reg.rotation.T + reg.translation
    assert np.mean(m.distance(mapped)) < 1e-4
    assert np.isclose(np.linalg.det(reg.rotation), 1.0) and np.allclose(reg.rotation.T @ reg.rotation, np.eye(3))
    # ... and equals the true one up to a symmetry of the surface
    R_true = np.array(truth["rotation"])
    assert min(np.linalg.norm(reg.rotation - g @ R_true) for g in m.symmetries) < 0.02


def test_no_candidates_rejects_the_model():
    m = load_model("ellipsoid")
    table = CurvatureTable(m.table_samples())
    saddle = load_model("monkey-saddle")
    touch = simulate_touch(saddle, (0.3, 0.3), points=61, spacing=0.02, rng=1)   # k1 > 0 > k2: no ellipsoid match
    reg = closedform_paper.register(m, table, estimate(touch), touch.points)
    assert not reg.ok and reg.rejected == "no candidates" and reg.to_json()["error"] is None
