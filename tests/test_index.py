"""The catalogue's index of places: rings read on a mesh as a touch reads them, and the true place
among the first a touch screens."""

import numpy as np
import pytest
import trimesh

from tactrec.bench.common import vertex_touch
from tactrec.features import Touch
from tactrec.index import ARCS_MM, PlaceIndex, model_rings, touch_rings
from tactrec.surfaces.mesh_rings import PlaceRings
from tactrec.methods.fast_config import FastConfig
from tactrec.simulation import simulate_touch
from tactrec.surfaces.mesh import MeshModel

J = len(ARCS_MM)


@pytest.fixture(scope="module")
def sphere():
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=40.0)
    return MeshModel(mesh.vertices, mesh.faces, name="sphere", units="mm")


def test_a_sphere_s_rings_are_its_curvature_on_every_place_and_in_every_touch(sphere):
    # on a sphere of radius R a section through the normal is a great circle: at arc s it lies
    # R (1 - cos(s / R)) below the tangent plane in every direction
    # (within what the facets allow: two sagittas of an edge, per unit of arc: the section runs
    # inside the sphere, the vertex on it)
    R, s = 40.0, np.asarray(ARCS_MM)
    expected = -R * (1.0 - np.cos(s / R)) / s
    within = 2.0 * sphere.edge_lengths.max() ** 2 / (8.0 * R) / s
    rings = model_rings(sphere)
    assert np.all(np.abs(rings.features[:, :J] - expected) <= within)
    assert np.all(rings.features[:, J:] <= within)
    rng = np.random.default_rng(3)
    for vertex in rng.choice(len(sphere.vertices), 5, replace=False):
        data = simulate_touch(sphere, [int(vertex)], points=81, spacing=0.3, angle=60.0, rng=rng)
        got = touch_rings(Touch.from_data(data), 1)
        assert np.all(np.abs(got[:J] - expected) <= within) and np.all(got[J:] <= within)


def test_a_touch_s_rings_do_not_depend_on_its_frame_and_flip_with_its_normal(scans):
    entry = scans.entries[1]
    _, data = vertex_touch(entry, 1, 0, 0)
    touch = Touch.from_data(data)
    turn = trimesh.transformations.random_rotation_matrix(np.random.default_rng(5).random(3))[:3, :3]
    moved = Touch.from_data(data.transformed(turn, np.array([5.0, -2.0, 7.0])))
    assert np.allclose(touch_rings(touch, 1), touch_rings(moved, 1), atol=1e-9, equal_nan=True)
    a, b = touch_rings(touch, 1), touch_rings(touch, -1)
    assert np.allclose(a[:J], -b[:J], equal_nan=True) and np.allclose(a[J:], b[J:], equal_nan=True)


def test_a_touch_s_true_place_is_among_the_first_round_of_the_index(scans):
    """Over 24 seeded P3 touches of four scans, the place nearest the true contact (same side of the
    surface) is among the first round's places for most, ranked over all four scans' places."""
    index = PlaceIndex(scans.entries)
    first, found = FastConfig.index_round, []
    for m, entry in enumerate(scans.entries):
        model = entry.model
        for instance in range(6):
            vertex, data = vertex_touch(entry, m, instance, 0)
            touch = Touch.from_data(data)
            ranked = index.ranked(touch, range(len(scans.entries)), len(index))
            rows = np.flatnonzero(ranked.model == m)
            place = ranked.vertex[rows]
            near = np.linalg.norm(model.vertices[place] - model.vertices[vertex], axis=1) <= 3.0
            facing = np.sum(model.fine_curvatures.normal[place] * model.fine_curvatures.normal[vertex], axis=1) > 0.8
            hits = rows[near & facing]
            found.append(hits[0] < first if len(hits) else False)
    assert np.mean(found) >= 0.8, f"{np.mean(found):.2f} of the true places in the first round"


def test_stored_rings_are_the_rings_and_bad_ones_are_refused(sphere):
    rings = model_rings(sphere)
    back = PlaceRings.from_store(rings.to_store(), len(sphere.vertices))
    assert np.array_equal(back.places, rings.places) and np.array_equal(back.features, rings.features)
    bad = dict(rings.to_store(), rings_places=rings.places + len(sphere.vertices))
    with pytest.raises(ValueError, match="rings"):
        PlaceRings.from_store(bad, len(sphere.vertices))


def test_a_face_many_parts_share_is_never_sure_whatever_the_catalogue_s_order():
    """Four boxes of other sizes, whose flat faces read alike to the index, the touched one last in
    the catalogue, so that the first round's places all lie on the others: 20 seeded noise-free
    touches on its top face, whose 12 mm curves stay on the face.  Every box fits each touch, so
    none may come back sure (>= 0.95), and before the search stops every box is posed (the touched
    one among them), however the index orders equal readings."""
    from tactrec.recognition import ModelEntry, Recognizer
    from tactrec.tables import CurvatureTable

    entries = []
    for name, extents in (("a", (70.0, 60.0, 50.0)), ("b", (80.0, 50.0, 40.0)), ("c", (60.0, 60.0, 60.0)),
                          ("touched", (60.0, 60.0, 40.0))):
        box = trimesh.creation.box(extents)
        v, f = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, max_edge=2.0)
        model = MeshModel(np.asarray(v), np.asarray(f), name=name, units="mm")
        entries.append(ModelEntry(model, CurvatureTable(model.table_samples())))
    assert len(PlaceIndex(entries[:3])) > FastConfig.index_round
    model = entries[-1].model
    top = np.flatnonzero((model.vertices[:, 2] > 19.9) & (np.abs(model.vertices[:, :2]).max(axis=1) < 12.0))
    rng = np.random.default_rng(12)
    with Recognizer(entries) as recognizer:
        for site in rng.choice(top, 20, replace=False):
            result = recognizer.recognize(simulate_touch(model, [int(site)], points=41, spacing=0.3, rng=rng))
            assert result.confidence < 0.95
            assert {r.model for r in result.ranking if r.ok} == {"a", "b", "c", "touched"}
