"""A mesh offset by a round tip's radius, as the search of a tip's touch sees it (:mod:`tactrec.surfaces.mesh_offset`)."""

import numpy as np
import pytest
import trimesh

from tactrec.cli import main
from tactrec.database import build_database, load_database
from tactrec.surfaces.mesh import MeshModel
from tactrec.surfaces.mesh_field import build_field
from tactrec.surfaces.mesh_offset import offset_curvature, stored_offset_field

RADIUS = 20.0
TIP = 3.0


@pytest.fixture(scope="module")
def sphere():
    tm = trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)
    return MeshModel(np.asarray(tm.vertices), np.asarray(tm.faces), name="sphere")


def test_the_offset_curvature_is_the_offset_surfaces():
    """A radius rho becomes rho + r where convex (kappa = -1/rho), rho - r where concave; a hollow at or
    tighter than the tip is no place for its centre (infinite)."""
    k = np.array([-0.1, 0.1, 0.0, 0.5, 0.6])
    np.testing.assert_allclose(offset_curvature(k, 2.0), [-1 / 12, 1 / 8, 0.0, np.inf, np.inf])
    assert np.isclose(offset_curvature(np.array([0.25]), 2.0)[0], 0.5)                  # radius 4 - 2


def test_an_offset_sphere_is_the_sphere_of_radius_plus_the_tip(sphere):
    """The sphere of 20 offset by 3: its places lie at 23, its curvatures are -1/23 where the mesh's are
    about -1/20, and its field is the distance to the sphere of 23 within the field's interpolation
    error, across the whole band."""
    view = sphere.offset(TIP)
    assert sphere.offset(TIP) is view                              # made once, kept
    np.testing.assert_allclose(np.linalg.norm(view.vertices, axis=1), RADIUS + TIP, atol=0.02)
    for own, offset in zip(sphere.fine_curvatures[:2], view.fine_curvatures[:2]):
        assert abs(np.median(own) * RADIUS + 1) < 0.02
        assert abs(np.median(offset) * (RADIUS + TIP) + 1) < 0.02
    field = view.distance_field
    rng = np.random.default_rng(0)
    u = rng.normal(size=(4000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    d = rng.uniform(-0.8, 0.8, 4000) * field.band
    p = u * (RADIUS + TIP + d)[:, None]
    error = np.abs(field.signed(p) - d)
    # the mesh's own distance is off the round sphere's by its facets' sag (h^2 / 8R): about 0.03 here
    assert np.median(error) < 0.05 and np.max(error) < 0.15
    # far from the offset surface (the centre) the field is its band
    np.testing.assert_array_equal(field.distance(np.array([[0.0, 0.0, 0.0]])), field.band)
    # its exact distances are the offset sphere's, along the mesh's planes
    sd, n = view.planes(p)
    np.testing.assert_allclose(n, sphere.planes(p)[1])
    assert np.median(np.abs(sd - d)) < 0.05 and np.median(np.abs(view.distance(p) - np.abs(d))) < 0.05


@pytest.mark.parametrize("offset", [0.0, TIP])
def test_the_brick_pre_filter_keeps_every_brick_the_full_sampling_keeps(sphere, monkeypatch, offset):
    """The field built with the pre-filter (one unsigned query per brick's centre) is, array for array,
    the field built by sampling every candidate brick (the pre-filter told every centre lies on the
    surface, so it drops none)."""
    import igl

    filtered = build_field(sphere.vertices, sphere.faces, mean_edge=sphere.mean_edge, offset=offset)
    query = igl.point_mesh_squared_distance
    monkeypatch.setattr(igl, "point_mesh_squared_distance",
                        lambda p, v, f: (np.full(len(p), offset ** 2),) + tuple(query(p, v, f)[1:]))
    full = build_field(sphere.vertices, sphere.faces, mean_edge=sphere.mean_edge, offset=offset)
    for a, b in zip(filtered.to_store().values(), full.to_store().values()):
        np.testing.assert_array_equal(a, b)


def test_a_database_stores_the_offset_fields_of_its_tips(tmp_path, sphere, capsys):
    """``tactrec build --tip-radius`` stores each mesh's offset field: loaded, it is the one built, and
    a rebuild with other radii rebuilds the mesh."""
    path = tmp_path / "ball.ply"
    trimesh.Trimesh(sphere.vertices, sphere.faces).export(path)
    db = tmp_path / "db"
    assert main(["build", str(path), "--out", str(db), "--tip-radius", "2", str(TIP), "--quiet"]) == 0
    model = load_database(db).entries[0].model
    stored = stored_offset_field(model._stored_field, TIP)
    assert stored is not None and stored_offset_field(model._stored_field, 1.0) is None
    built = build_field(model.vertices, model.faces, mean_edge=model.mean_edge, spacing=model.distance_field.spacing,
                        offset=TIP)
    for a, b in zip(stored.to_store().values(), built.to_store().values()):
        np.testing.assert_array_equal(a, b)
    view = model.offset(TIP)
    np.testing.assert_array_equal(view.distance_field.bricks, built.bricks)
    assert build_database([path], db, quiet=True, tips=[2.0, TIP]).reused == ["ball"]
    assert build_database([path], db, quiet=True, tips=[1.0]).built == ["ball"]
    assert main(["build", str(path), "--out", str(tmp_path / "bad"), "--tip-radius", "-1"]) == 2
    assert "tip radius" in capsys.readouterr().err


def test_a_recognizer_prepares_the_offset_fields_of_its_tips():
    """``Recognizer(tips=...)`` builds each mesh's offset field before any recognition (and before its
    workers fork); other radii are left to their first touch."""
    from tactrec.recognition import ModelEntry, Recognizer
    from tactrec.tables import CurvatureTable

    tm = trimesh.creation.icosphere(subdivisions=3, radius=RADIUS)
    model = MeshModel(np.asarray(tm.vertices), np.asarray(tm.faces), name="ball")
    with Recognizer([ModelEntry(model, CurvatureTable(model.table_samples()))], tips=(TIP,)):
        assert "distance_field" in model.offset(TIP).__dict__
        assert "distance_field" not in model.offset(1.0).__dict__


def test_the_places_of_one_offset_never_serve_another():
    """The same centres searched with tips of 2 and 3 and as bare points, one after the other in one
    process (whose place cache outlives a touch): each gets the places of its own surface, as a fresh
    cache gives them, and those of the three surfaces differ."""
    import dataclasses

    from tactrec.features import Touch
    from tactrec.methods.fast import FastConfig
    from tactrec.methods.fast_stages import ranked_places
    from tactrec.runner import Held
    from tactrec.sensor import Imperfections
    from tactrec.simulation import simulate_random_touch

    from conftest import small_meshes

    entries = small_meshes()[:1]
    model, config = entries[0].model, FastConfig()
    data = simulate_random_touch(model, rng=np.random.default_rng(5), points=41, spacing=0.3, angle=60.0,
                                 imperfections=Imperfections(tip_radius=2.0))
    shared, found = Held(entries), []
    for tip in (2.0, 3.0, 0.0):
        touch = Touch.from_data(dataclasses.replace(data, tip_radius=tip))
        seen, view, g = touch.searched(model, 1)
        got = ranked_places(shared, 0, seen, view, g, 1, config, "screen", None)
        alone = ranked_places(Held(entries), 0, seen, view, g, 1, config, "screen", None)
        np.testing.assert_array_equal(got, alone)
        found.append(got)
    assert not np.array_equal(found[0], found[1]) and not np.array_equal(found[0], found[2])


@pytest.fixture(scope="module")
def ball_db(tmp_path_factory, sphere):
    """A database of the sphere, built with no tip radius."""
    folder = tmp_path_factory.mktemp("ball")
    path = folder / "ball.ply"
    trimesh.Trimesh(sphere.vertices, sphere.faces).export(path)
    build_database([path], folder / "db", quiet=True)
    return folder / "db"


@pytest.mark.parametrize("tip", [0.5, TIP, 9.0, 14.0])
def test_a_tip_reads_the_offset_within_its_band_and_builds_nothing_up_to_the_reach(ball_db, monkeypatch, tip):
    """On a database built with no tip radius, a tip up to the reach (10 mm) reads its offset's field
    from what the database stores, building nothing: its distances are those of the sphere of 20 + r
    across the field's band (within the interpolation of its cells and the facets' kinks).  A larger
    tip's field is built on first use."""
    import tactrec.surfaces.mesh_offset as mesh_offset
    from tactrec.surfaces.mesh_offset import REACH

    model = load_database(ball_db).entries[0].model                  # a fresh model: nothing read yet
    built = []
    monkeypatch.setattr(mesh_offset, "build_field", lambda *a, **k: built.append(k) or build_field(*a, **k))
    field = model.offset(tip).distance_field
    assert (len(built) > 0) == (tip > REACH)
    rng = np.random.default_rng(3)
    u = rng.normal(size=(4000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    d = rng.uniform(-0.8, 0.8, 4000) * field.band
    p = u * (RADIUS + tip + d)[:, None]
    exact = model.offset(tip).planes(p)[0]                     # the mesh's distance less the tip
    assert field.band >= 0.5 * model.distance_field.truncation
    error = np.abs(field.signed(p) - exact)
    assert np.median(error) < 0.02 and np.max(error) < 0.06
