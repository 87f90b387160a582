"""The one point-to-plane solver (:mod:`tactrec.registration.solver`) on both kinds of surface."""

import numpy as np
import pytest
import trimesh

from tactrec.registration.result import rotations_from_vectors
from tactrec.registration.solver import Criteria, mean_distance, solve
from tactrec.registration.step import jacobian
from tactrec.simulation import simulate_touch
from tactrec.surfaces import load_model
from tactrec.surfaces.mesh import MeshModel


def _ellipsoid_mesh() -> MeshModel:
    tm = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    return MeshModel(np.asarray(tm.vertices) * [40.0, 28.0, 20.0], np.asarray(tm.faces), name="ellipsoid-mesh")


def _perturbed(R, t, centre, rng, *, degrees, shift):
    """Poses near ``R, t``: turned by ``degrees`` about the data's centre and shifted by ``shift``."""
    axes = rng.normal(size=(20, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    dR = rotations_from_vectors(np.deg2rad(degrees) * axes)
    c = R @ centre + t
    R2 = dR @ R
    t2 = np.einsum("hij,j->hi", dR, t - c) + c + shift * rng.normal(size=(20, 3)) / np.sqrt(3)
    return R2, t2


@pytest.mark.parametrize("kind", ["closed-form", "mesh"])
def test_solver_brings_20_perturbed_poses_back_to_the_truth(kind):
    if kind == "mesh":
        model = _ellipsoid_mesh()
        site, spacing, shift, tol = [1234.0], 0.4, 1.0, 1e-4
    else:
        model = load_model("ellipsoid")
        site, spacing, shift, tol = (0.8, 1.0), 0.02, 0.03, 1e-4
    touch = simulate_touch(model, site, points=31, spacing=spacing, rng=3)
    truth = touch.meta["truth"]
    R0, t0 = np.asarray(truth["rotation"]), np.asarray(truth["translation"])
    x = touch.points
    R, t = _perturbed(R0, t0, x.mean(axis=0), np.random.default_rng(5), degrees=4.0, shift=shift)
    before = mean_distance(model, R, t, x)
    fit = solve(model, R, t, x, Criteria(30, tolerance=1e-9))
    moved, truth_moved = np.einsum("hij,mj->hmi", fit.R, x) + fit.t[:, None], x @ R0.T + t0
    landed = np.max(np.linalg.norm(moved - truth_moved, axis=2), axis=1) < tol * model.size
    if kind == "closed-form":                   # at least 19 of 20 land on the true pose
        assert landed.sum() >= 19, np.max(np.linalg.norm(moved - truth_moved, axis=2), axis=1)
    else:
        # a faceted surface has shallow minima a facet away from the truth, fits within 2e-5 x its size:
        # every pose ends on a fit that good, and most on the truth itself
        assert np.all(fit.error < 2e-5 * model.size) and landed.sum() >= 10, (fit.error, landed)
        assert np.all(before > 1e-3 * model.size)
    assert np.all(fit.error <= before + 1e-12)
    assert np.allclose(np.einsum("hji,hjk->hik", fit.R, fit.R), np.eye(3), atol=1e-9)


def test_predicted_errors_match_the_exact_ones_once_converged():
    model = _ellipsoid_mesh()
    touch = simulate_touch(model, [777.0], points=31, spacing=0.4, rng=1)
    truth = touch.meta["truth"]
    R, t = _perturbed(np.asarray(truth["rotation"]), np.asarray(truth["translation"]), touch.points.mean(axis=0),
                      np.random.default_rng(2), degrees=2.0, shift=0.5)
    exact = solve(model, R, t, touch.points, Criteria(25))
    predicted = solve(model, R, t, touch.points, Criteria(25, predict=True))
    assert np.allclose(exact.R, predicted.R) and np.allclose(exact.t, predicted.t)
    assert np.allclose(predicted.error, exact.error, atol=1e-3 * np.median(model.edge_lengths))
    # the predicted errors spare the last query of every point
    assert predicted.queries < exact.queries


def test_a_pose_without_planes_stops_where_it_is_and_scores_inf():
    class Singular:                            # a model whose planes vanish left of x = 0
        def planes(self, y):
            d, n = y[..., 2] - 1.0, np.broadcast_to([0.0, 0.0, 1.0], y.shape).copy()
            d = np.where(y[..., 0] < 0, np.nan, d)
            return d, n

        def distance(self, y):
            return np.where(y[..., 0] < 0, np.nan, np.abs(y[..., 2] - 1.0))

    x = np.array([[1.0, 0.0, 0.0], [2.0, 1.0, 0.0], [3.0, -1.0, 0.0], [2.0, 0.0, 0.0]])
    R = np.stack([np.eye(3), np.eye(3)])
    t = np.array([[0.0, 0.0, 0.3], [-10.0, 0.0, 0.3]])
    fit = solve(Singular(), R, t, x, Criteria(10))
    assert fit.error[0] < 1e-9 and np.isinf(fit.error[1])
    assert np.array_equal(fit.R[1], R[1]) and np.array_equal(fit.t[1], t[1])


def test_jacobian_is_the_derivative_of_the_plane_distances():
    rng = np.random.default_rng(0)
    y, n = rng.normal(size=(7, 3)), rng.normal(size=(7, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    J = jacobian(y, n)
    w, v, h = rng.normal(size=3), rng.normal(size=3), 1e-6
    moved = y @ rotations_from_vectors((h * w)[None])[0].T + h * v
    assert np.allclose(np.sum((moved - y) * n, axis=1) / h, J @ np.r_[w, v], atol=1e-5)


@pytest.mark.parametrize("bad", [dict(iterations=-1), dict(iterations=2.5), dict(iterations=3, tolerance=-1.0),
                                 dict(iterations=3, history=-1), dict(iterations=3, history=1.5),
                                 dict(iterations=3, tolerance=float("nan"))])
def test_criteria_refuse_bad_values(bad):
    with pytest.raises(ValueError):
        Criteria(**bad)


def test_a_step_is_the_least_squares_step_of_the_plane_residuals():
    """On well-posed plane residuals the compiled step is the least-squares step ``min |r + J d|``
    (the damping only holds directions no residual constrains), the turn applied by Rodrigues'
    formula, the residuals predicted as ``r + J d``; where every plane is parallel (a flat patch:
    three directions free) the step stays finite and still lowers the residuals."""
    from tactrec.registration.solver import step

    rng = np.random.default_rng(11)
    R = rotations_from_vectors(rng.normal(size=(20, 3)))
    t = rng.normal(size=(20, 3)) * 5.0
    moved = rng.normal(size=(20, 15, 3)) * 8.0
    n = rng.normal(size=(20, 15, 3))
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    r = rng.normal(size=(20, 15)) * 0.1
    R2, t2, delta, after = step(R, t, moved, n, r)
    J = jacobian(moved, n)
    d = np.array([np.linalg.lstsq(J[h], -r[h], rcond=None)[0] for h in range(len(J))])
    assert np.all(np.abs(delta - d).max(axis=1) <= 1e-3 * np.abs(d).max(axis=1))      # within 0.1%
    dR = rotations_from_vectors(delta[:, :3])
    np.testing.assert_allclose(R2, dR @ R, atol=1e-12)
    np.testing.assert_allclose(t2, np.einsum("hij,hj->hi", dR, t) + delta[:, 3:], atol=1e-10)
    np.testing.assert_allclose(after, r + np.einsum("hmi,hi->hm", J, delta), atol=1e-10)
    flat = np.broadcast_to([0.0, 0.0, 1.0], n.shape).copy()
    _, _, delta, after = step(R, t, moved, flat, r)
    assert np.all(np.isfinite(delta))
    assert np.all((after ** 2).sum(axis=1) < (r ** 2).sum(axis=1))


def test_anderson_acceleration_fits_scans_closer_in_the_same_steps(scans):
    """On a scan's facets a plain step slides a weakly held pose a few per cent of the way; ten
    accelerated steps end far closer to the truth, and no pose ends worse than it started."""
    from tactrec.simulation import simulate_random_touch

    ratios, better = [], []
    for name in ("banana", "hammer"):
        model = scans.get(name).model
        for seed in range(3):
            touch = simulate_random_touch(model, rng=np.random.default_rng(seed), points=41, spacing=0.3, angle=30.0,
                                          noise=0.0, outward=True)
            truth = touch.meta["truth"]
            x = touch.points
            R, t = _perturbed(np.asarray(truth["rotation"]), np.asarray(truth["translation"]), x.mean(axis=0),
                              np.random.default_rng(seed), degrees=3.0, shift=1.0)
            before = mean_distance(model, R, t, x)
            plain = solve(model, R, t, x, Criteria(10, tolerance=1e-9))
            fast = solve(model, R, t, x, Criteria(10, tolerance=1e-9, history=3))
            assert np.all(fast.error <= before)
            ratios.append(np.median(fast.error) / np.median(plain.error))
            better.append(np.mean(fast.error < plain.error))
    assert np.max(ratios) < 0.8 and np.median(ratios) < 0.4, ratios
    assert np.mean(better) > 0.9, better
