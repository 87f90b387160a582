"""The distance field of a mesh and the engine's compiled kernels (:mod:`tactrec.engine`)."""

import numpy as np
import pytest
import trimesh

from tactrec.engine.kernels import field_best, field_refine, screen_rotations
from tactrec.surfaces.field_kernels import field_gradient
from tactrec.registration.result import rotations_from_vectors
from tactrec.registration.solver import mean_distance
from tactrec.surfaces.mesh import MeshModel
from tactrec.surfaces.mesh_field import DistanceField

RADIUS = 30.0


@pytest.fixture(scope="module")
def sphere():
    tm = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS)
    return MeshModel(np.asarray(tm.vertices), np.asarray(tm.faces), name="sphere")


@pytest.fixture(scope="module")
def open_cylinder():
    from test_mesh import grid_cylinder

    tm = grid_cylinder()
    return MeshModel(np.asarray(tm.vertices), np.asarray(tm.faces), name="cylinder")


def _band_points(model, rng, count, spread):
    """Points within ``spread`` of random surface points, along the face normals."""
    face = rng.integers(0, len(model.faces), count)
    b = rng.dirichlet([1.0, 1.0, 1.0], count)
    p = np.einsum("ij,ijk->ik", b, model.vertices[model.faces[face]])
    return p + model.face_normals[face] * rng.uniform(-spread, spread, count)[:, None]


def test_the_field_is_the_signed_distance_within_its_interpolation_error(sphere):
    field = sphere.distance_field
    p = _band_points(sphere, np.random.default_rng(0), 5000, 0.8 * field.truncation)
    exact = sphere.distance(p) * np.sign(np.linalg.norm(p, axis=1) - RADIUS)       # outside positive
    kept = np.abs(exact) < field.truncation - 2 * field.spacing                     # no corner clipped
    error = np.abs(field.signed(p) - exact)[kept]
    # trilinear interpolation of a smooth distance: off by about h^2 |kappa| / 8; a polyhedron's
    # distance has kinks inside, beside its edges, where it is off by a few per cent of the spacing
    assert np.median(error) < 2 * (field.spacing ** 2 / RADIUS / 8 + field.quantum)
    assert np.percentile(error, 99) < 0.015 * field.spacing
    assert np.max(error) < 0.05 * field.spacing


def test_far_from_the_surface_the_field_is_its_truncation(sphere):
    field = sphere.distance_field
    far = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, RADIUS + 2 * field.truncation], [1e4, 0, 0], [np.nan, 0, 0]])
    np.testing.assert_array_equal(field.distance(far), field.truncation)


def test_an_open_scan_is_signed_by_the_side_of_its_normal(open_cylinder):
    field = open_cylinder.distance_field
    p = _band_points(open_cylinder, np.random.default_rng(1), 2000, 0.8 * field.truncation)
    p = p[np.abs(p[:, 2]) < 25]                                                    # away from the open rims
    exact = open_cylinder.planes(p)[0]          # the side of the closest face's normal
    d = field.signed(p)
    sure = np.abs(exact) > 0.05 * field.spacing
    assert np.all(np.sign(d[sure]) == np.sign(exact[sure]))
    assert np.all(np.sign(exact[sure]) == np.sign(np.hypot(p[sure, 0], p[sure, 1]) - 15.0))   # outward


def test_the_gradient_is_the_fields_and_a_unit_normal_near_the_surface(sphere):
    field = sphere.distance_field
    p = _band_points(sphere, np.random.default_rng(2), 200, 0.5 * field.truncation)
    d, g = field_gradient(*field.args(), p)
    np.testing.assert_allclose(d, field.signed(p))
    e = 1e-5
    numeric = np.stack([(field.signed(p + e * np.eye(3)[k]) - field.signed(p - e * np.eye(3)[k])) / (2 * e)
                        for k in range(3)], axis=1)
    inside = np.all(np.abs(numeric - g) < 1e-4, axis=1)                            # not on a cell face
    assert inside.mean() > 0.95
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=0.02)
    np.testing.assert_allclose(g / np.linalg.norm(g, axis=1, keepdims=True),
                               p / np.linalg.norm(p, axis=1, keepdims=True), atol=0.02)


@pytest.mark.parametrize("offset", [0.0, 1.5])
def test_every_sample_is_libigls_signed_distance_clipped_to_the_band(scans, offset):
    """A scan's field, and the field of the scan offset by 1.5 mm (a tip's centres): 20,000 of its
    samples, drawn at random, against libigl's signed distance (pseudonormal) at the same points, less
    the offset and clipped to the band: equal to the quantum."""
    import igl

    from tactrec.surfaces.field_kernels import BRICK
    from tactrec.surfaces.mesh_field import build_field

    model = scans.entries[1].model                                                   # the mug
    field = build_field(model.vertices, model.faces, mean_edge=model.mean_edge, offset=offset)
    rng = np.random.default_rng(5)
    brick = rng.integers(0, len(field.bricks), 20_000)
    at = rng.integers(0, BRICK + 1, (20_000, 3))
    where = np.argwhere(field.index >= 0)[np.argsort(field.index[field.index >= 0])][brick]
    p = field.origin + (where * BRICK + at) * field.spacing
    exact, *_ = igl.signed_distance(p, model.vertices, model.faces, sign_type=igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)
    expected = np.clip(np.asarray(exact) - offset, -field.truncation, field.truncation)
    stored = field.bricks[brick, at[:, 0], at[:, 1], at[:, 2]] * field.quantum
    assert np.max(np.abs(stored - expected)) <= 0.5 * field.quantum * (1 + 1e-6)


def test_the_field_survives_storage_and_a_malformed_one_is_refused(sphere):
    field = sphere.distance_field
    again = DistanceField.from_store(field.to_store())
    p = _band_points(sphere, np.random.default_rng(3), 100, 1.0)
    np.testing.assert_array_equal(again.signed(p), field.signed(p))
    for key, bad in [("field_bricks", field.bricks.astype(np.float32)),
                     ("field_index", field.index + len(field.bricks)),
                     ("field_spacing", np.array(-1.0)), ("field_origin", np.zeros(2))]:
        with pytest.raises(ValueError, match="distance field"):
            DistanceField.from_store(dict(field.to_store(), **{key: bad}))


def test_the_screen_keeps_each_places_least_mean_truncated_distance(sphere):
    field = sphere.distance_field
    rng = np.random.default_rng(4)
    local = rng.normal(size=(7, 3)) * [5.0, 5.0, 0.3]
    places = sphere.vertices[:50]
    normals = sphere.vertex_normals[:50]
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    d1 = helper - np.sum(helper * normals, axis=1, keepdims=True) * normals
    d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
    frames = np.stack([d1, np.cross(normals, d1), normals], axis=2)
    turned = screen_rotations(local, 12)
    best, which = field_best(*field.args(), np.ascontiguousarray(frames), np.ascontiguousarray(places), turned)
    moved = np.einsum("nij,rmj->nrmi", frames, turned) + places[:, None, None]
    every = np.abs(field.signed(moved)).mean(axis=-1)                  # (n, r): every point of every turn
    np.testing.assert_allclose(best, every.min(axis=1), rtol=1e-6)
    np.testing.assert_allclose(every[np.arange(len(best)), which], every.min(axis=1), rtol=1e-6)
    assert len(np.unique(which)) > 3                                   # the places' best turns differ


def test_gauss_newton_on_the_field_recovers_a_perturbed_pose_on_a_scan(scans):
    model = scans.get("banana").model
    field = model.distance_field
    rng = np.random.default_rng(5)
    ok = 0
    for trial in range(20):
        centre = model.vertices[rng.integers(len(model.vertices))]
        x = model.vertices[np.argsort(np.linalg.norm(model.vertices - centre, axis=1))[:60]]
        R = rotations_from_vectors(np.deg2rad(3.0) * rng.normal(size=(1, 3)) / np.sqrt(3))
        t = centre - R[0] @ centre + rng.normal(size=3) * 0.5
        before = mean_distance(model, R, t[None], x)[0]
        R2, t2, score = field_refine(*field.args(), R, t[None], x, 10)
        after = mean_distance(model, R2, t2, x)[0]
        ok += after < min(0.05, before / 4)
    assert ok >= 18


def test_tilted_normals_ring_the_data_normal_at_the_tilt_step():
    """Every tilted normal is a unit vector on a ring ``step, 2 step, ...`` degrees off the data's,
    out to the cone; neighbours on a ring lie about a step apart; the data's own is not among them."""
    from tactrec.engine.screen import tilted_normals

    normal = np.array([0.2, -0.3, 0.93])
    normal /= np.linalg.norm(normal)
    tilted = np.stack(tilted_normals(normal, np.array([1.0, 0.0, 0.0]), cone=60.0, step=20.0))
    np.testing.assert_allclose(np.linalg.norm(tilted, axis=1), 1.0, atol=1e-12)
    off = np.degrees(np.arccos(np.clip(tilted @ normal, -1, 1)))
    rings, counts = np.unique(off.round(6), return_counts=True)
    np.testing.assert_allclose(rings, [20.0, 40.0, 60.0], atol=1e-6)
    for ring, count in zip(rings, counts):
        on = tilted[np.abs(off - ring) < 1e-6]
        gap = np.degrees(np.arccos(np.clip(np.sum(on * np.roll(on, 1, axis=0), axis=1), -1, 1)))
        assert count >= 6 and np.all(gap < 1.3 * 20.0) and np.all(gap > 0.7 * 20.0 * min(1.0, count / 6))


def test_a_local_screen_keeps_a_coarse_pose_within_the_exact_steps_reach():
    """Touches on a coarse ellipsoid (7 mm edges), poses 6-10 degrees and up to a millimetre off the
    truth (a coarse grid's error): each seed's best pose on the local grid (12 degrees, 1.5 mm,
    5**6 poses) scores no worse on the field than the seed, lies within the grid, and exact steps
    from it lay the curves within 0.005 mm of the surface on at least 18 of 20 touches."""
    from tactrec.engine.screen import local_screen
    from tactrec.features import Touch
    from tactrec.registration.solver import Criteria, solve
    from tactrec.simulation import simulate_random_touch

    tm = trimesh.creation.icosphere(subdivisions=2, radius=1.0).apply_scale([30.0, 24.0, 18.0])
    model = MeshModel(np.asarray(tm.vertices), np.asarray(tm.faces), name="egg", units="mm")
    rng = np.random.default_rng(8)
    fitted = 0
    for trial in range(20):
        data = simulate_random_touch(model, rng=rng, points=41, spacing=0.3, angle=60.0)
        touch = Touch.from_data(data)
        Rt, tt = (np.asarray(data.meta["truth"][k]) for k in ("rotation", "translation"))
        axis = rng.normal(size=3)
        turn = rotations_from_vectors(np.deg2rad(rng.uniform(6.0, 10.0)) * axis[None] / np.linalg.norm(axis))[0]
        contact = touch.geometry.contact
        R = (turn @ Rt)[None]
        t = (Rt @ contact + tt + rng.uniform(-1.0, 1.0, 3) - R[0] @ contact)[None]
        x = touch.subset(5)
        Rb, tb, score, lookups = local_screen(model, R, t, x, contact, angle=12.0, shift=1.5)
        assert score[0] <= field_refine(*model.distance_field.args(), R, t, x, 0)[2][0]
        moved = np.degrees(np.arccos(np.clip((np.trace(Rb[0] @ R[0].T) - 1) / 2, -1, 1)))
        assert moved <= 12.0 * np.sqrt(3) + 1e-6
        fitted += solve(model, Rb, tb, touch.points, Criteria(20)).error[0] < 0.005
    assert fitted >= 18


def test_the_preload_loads_every_kernel_a_search_calls(scans):
    """``engine.preload`` (what ``tactrec recognize`` runs while its database loads) leaves every
    kernel compiled for the argument types a search passes: a search adds no signature."""
    from tactrec.engine import kernels, preload
    from tactrec.recognition import Recognizer
    from tactrec.simulation import simulate_random_touch

    from tactrec.registration import anderson, step
    from tactrec.surfaces import field_kernels

    preload().join()
    compiled = [getattr(kernels, name) for name in ("screen_rotations", "field_best", "field_refine")]
    compiled += [field_kernels.field_lookup, field_kernels.field_gradient, step.plane_step, step._rows,
                 anderson.anderson]

    def signatures():
        return {kernel.__name__: list(kernel.signatures) for kernel in compiled}

    loaded = signatures()
    assert all(len(s) == 1 for s in loaded.values())
    depth = 0
    with Recognizer(scans.entries) as recognizer:
        for seed in range(10):                                        # until a search screens on the fields
            touch = simulate_random_touch(scans.entries[seed % len(scans.entries)].model,
                                          rng=np.random.default_rng(seed), points=41, spacing=0.3, angle=30.0,
                                          noise=0.05, noise_kind="gaussian", outward=False)
            depth = recognizer.recognize(touch).depth
            if depth >= 2:
                break
    assert depth >= 2
    assert signatures() == loaded
