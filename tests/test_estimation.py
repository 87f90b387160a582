"""Normal and principal curvatures at the contact point (paper Section 3.1, METHOD section 2)."""

import numpy as np
import pytest

from tactrec.estimation import estimate, find_contact, principal_curvatures
from tactrec.simulation import simulate_touch
from tactrec.surfaces import load_model

UV = (1.21, 0.43)   # the paper's elliptic-paraboloid example (Section 4.3.1)


@pytest.fixture(scope="module")
def paraboloid():
    m = load_model("elliptic-paraboloid")
    k1, k2, n, _ = m.curvatures(np.array(UV[0]), np.array(UV[1]))
    return m, float(k1), float(k2), n


def _errors(touch, geom, k1, k2, n):
    R = np.array(touch.meta["truth"]["rotation"])          # data -> model
    return np.linalg.norm(R @ geom.normal - n), abs(geom.k1 - k1), abs(geom.k2 - k2)


@pytest.mark.parametrize("method", ["closed-form", "least-squares"])
def test_paper_example_without_noise_within_one_thousandth(paraboloid, method):
    m, k1, k2, n = paraboloid
    for seed in range(5):
        touch = simulate_touch(m, UV, points=61, spacing=0.004, noise=0.0, rng=seed)
        dn, dk1, dk2 = _errors(touch, estimate(touch, method=method), k1, k2, n)
        assert dn < 1e-3 and dk1 < 1e-3 and dk2 < 1e-3, (seed, dn, dk1, dk2)


def test_higher_degree_fit_removes_the_bias_on_long_curves(paraboloid):
    m, k1, k2, n = paraboloid
    touch = simulate_touch(m, UV, points=61, spacing=0.01, noise=0.0, rng=0)
    biased = _errors(touch, estimate(touch, window=None, degree=2), k1, k2, n)
    exact = _errors(touch, estimate(touch, window=None, degree=4), k1, k2, n)
    assert max(biased) > 5e-3 and max(exact) < 1e-3


def test_paper_example_with_paper_noise_within_paper_error(paraboloid):
    """Noise +/-0.001 (the paper's): |dk| <= 0.05, the paper's own error, on 20 seeds."""
    m, k1, k2, n = paraboloid
    for seed in range(20):
        touch = simulate_touch(m, UV, points=61, spacing=0.01, noise=0.001, rng=seed)
        dn, dk1, dk2 = _errors(touch, estimate(touch), k1, k2, n)
        assert dk1 <= 0.05 and dk2 <= 0.05 and dn < 0.02, (seed, dn, dk1, dk2)


def test_closed_form_equals_least_squares_for_three_curves():
    rng = np.random.default_rng(3)
    normal = np.array([0.0, 0.0, 1.0])
    for _ in range(20):
        k1, k2 = np.sort(rng.normal(size=2))[::-1]
        t0 = rng.uniform(0, np.pi)
        psi = rng.uniform(0, np.pi, size=3)
        tangents = np.stack([np.cos(psi), np.sin(psi), np.zeros(3)], axis=1)
        kn = k1 * np.cos(psi - t0) ** 2 + k2 * np.sin(psi - t0) ** 2
        a = principal_curvatures(tangents, normal, kn, method="closed-form")
        b = principal_curvatures(tangents, normal, kn, method="least-squares")
        assert np.allclose(a[:2], (k1, k2)) and np.allclose(b[:2], (k1, k2))
        d1 = np.array([np.cos(t0), np.sin(t0), 0.0])
        assert abs(abs(a[2][0] @ d1) - 1) < 1e-9 and abs(abs(b[2][0] @ d1) - 1) < 1e-9


def test_more_than_three_curves(paraboloid):
    m, k1, k2, n = paraboloid
    touch = simulate_touch(m, UV, points=61, spacing=0.004, curves=5, angle=36.0, rng=1)
    dn, dk1, dk2 = _errors(touch, estimate(touch), k1, k2, n)
    assert dn < 1e-3 and dk1 < 1e-3 and dk2 < 1e-3


def test_contact_found_from_the_curves(paraboloid):
    m, *_ = paraboloid
    touch = simulate_touch(m, UV, points=61, spacing=0.01, noise=0.001, contact=True, rng=4)
    found = find_contact(touch.curves)
    assert np.linalg.norm(found - touch.contact) < 2e-3


def test_orientation_from_outward_and_flip(paraboloid):
    m, k1, k2, n = paraboloid
    touch = simulate_touch(m, UV, points=61, spacing=0.004, rng=2)
    geom = estimate(touch)
    assert geom.oriented and geom.normal @ touch.outward > 0
    flipped = geom.flipped()
    assert np.allclose(flipped.normal, -geom.normal)
    assert np.isclose(flipped.k1, -geom.k2) and np.isclose(flipped.k2, -geom.k1)
    assert np.allclose(np.cross(*flipped.directions), flipped.normal)


def test_planes_ten_degrees_apart_still_give_an_estimate_one_degree_does_not(paraboloid):
    """The paper's P3 sweep goes down to planes 10 degrees apart; nearly coincident planes are refused."""
    from tactrec.errors import InputError

    m, k1, k2, n = paraboloid
    touch = simulate_touch(m, UV, points=61, spacing=0.004, angle=10.0, noise=0.0, rng=0)
    dn, dk1, dk2 = _errors(touch, estimate(touch), k1, k2, n)
    assert dn < 1e-3 and dk1 < 5e-3 and dk2 < 5e-3
    with pytest.raises(InputError, match="tangent to one another"):
        estimate(simulate_touch(m, UV, points=61, spacing=0.004, angle=1.0, noise=0.0, rng=0))


def test_mesh_sections_are_fitted_over_several_facets():
    """On a plane section of a triangle mesh (a polyline), the fit spans several straight pieces:
    the curvature is the surface's, not a single facet's kink."""
    import trimesh

    from tactrec.surfaces.mesh import MeshModel

    tm = trimesh.creation.icosphere(subdivisions=3, radius=30.0)          # edges about 4 mm
    m = MeshModel(tm.vertices, tm.faces, name="ball", units="mm")
    for v in (0, 100, 400):
        touch = simulate_touch(m, [v], points=81, spacing=0.3, rng=v)
        geom = estimate(touch)
        assert abs(geom.k1 + 1 / 30) < 0.006 and abs(geom.k2 + 1 / 30) < 0.006, (v, geom.k1, geom.k2)


def test_a_curves_fit_is_the_same_read_either_way():
    """A curve's sampling plane and fit do not depend on the order its points come in: e1 runs
    from the first point to the last (so it turns with them), and the tangent with it."""
    from scipy.spatial.transform import Rotation

    from tactrec.estimation import _sampling_plane, fit_curve

    R = 20.0
    s = np.linspace(-6.0, 6.0, 41)
    flat = np.stack([R * np.sin(s / R), np.zeros_like(s), R * (1.0 - np.cos(s / R))], axis=1)  # in y = 0
    arc = flat @ Rotation.from_rotvec([0.3, -0.5, 0.2]).as_matrix().T + [1.0, 2.0, 3.0]
    for curve in (arc, arc[::-1]):
        e1, e2, n = _sampling_plane(curve)
        assert e1 @ (curve[-1] - curve[0]) > 0
        assert np.allclose(np.cross(n, e1), e2) and np.max(np.abs((curve - curve[20]) @ n)) < 1e-9
    a, b = fit_curve(arc, arc[20]), fit_curve(arc[::-1], arc[20])
    assert np.allclose(a.tangent, -b.tangent, atol=1e-9)
    assert np.allclose(a.principal_normal, b.principal_normal, atol=1e-9)
    assert a.curvature == pytest.approx(b.curvature, rel=1e-9) and a.curvature == pytest.approx(1.0 / R, rel=5e-3)
