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
        np.testing.assert_allclose(offset, own / (1 - TIP * own))
    field = view.distance_field
    assert field.spacing == sphere.distance_field.spacing and field.truncation == sphere.distance_field.truncation
    rng = np.random.default_rng(0)
    u = rng.normal(size=(4000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    d = rng.uniform(-0.8, 0.8, 4000) * field.truncation
    p = u * (RADIUS + TIP + d)[:, None]
    error = np.abs(field.signed(p) - d)
    # the mesh's own distance is off the round sphere's by its facets' sag (h^2 / 8R): about 0.03 here
    assert np.median(error) < 0.05 and np.max(error) < 0.15
    # far from the offset surface (on the mesh itself, or the centre) the field is its truncation
    np.testing.assert_array_equal(field.distance(np.array([[0.0, 0.0, RADIUS], [0.0, 0.0, 0.0]])), field.truncation)


def test_the_base_field_is_the_offset_field_at_zero(sphere):
    """The brick pre-filter keeps every brick the full sampling keeps: the field of offset 0 is the
    model's own, array for array."""
    built = build_field(sphere.vertices, sphere.faces, mean_edge=sphere.mean_edge, offset=0.0)
    own = sphere.distance_field
    for a, b in zip(built.to_store().values(), own.to_store().values()):
        np.testing.assert_array_equal(a, b)


def test_a_database_stores_the_offset_fields_of_its_tips(tmp_path, sphere, capsys):
    """``tactrec build --tip-radius`` stores each mesh's offset field: loaded, it is the one built, a
    radius not stored is built on first use, and a rebuild with other radii rebuilds the mesh."""
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
    assert model.offset(1.0).distance_field.truncation == built.truncation                    # built now
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
