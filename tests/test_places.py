"""The field screen's places (tactrec.engine.screen.screen_places): every vertex of a mesh lies near
a place in position and in normal, so that some hypothesis poses the data's normal onto about the
surface's own wherever the contact lies, on a sharp edge or a thin part as on a smooth face."""

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from tactrec.engine.screen import screen_places
from tactrec.linalg import stable_order, stable_prefix
from tactrec.registration import mesh_fast
from tactrec.surfaces.mesh import MeshModel


def _model(tm, name):
    """The mesh ``tm`` as a model (its fields are built when a test first reads them)."""
    return MeshModel(np.asarray(tm.vertices), np.asarray(tm.faces), name=name)


@pytest.fixture(scope="module")
def shapes():
    """A block with sharp edges and corners, a plate 2 mm thick (a thin part: both faces within one
    cell), a smooth sphere and a cylinder, in facets of about 1 mm."""
    out = []
    for name, tm in (("block", trimesh.creation.box((40.0, 30.0, 20.0))),
                     ("plate", trimesh.creation.box((40.0, 30.0, 2.0))),
                     ("sphere", trimesh.creation.icosphere(subdivisions=5, radius=20.0)),
                     ("cylinder", trimesh.creation.cylinder(radius=10.0, height=40.0, sections=96))):
        v, f = trimesh.remesh.subdivide_to_size(tm.vertices, tm.faces, max_edge=1.0)
        out.append(_model(trimesh.Trimesh(v, f, process=True), name))
    return out


@pytest.mark.parametrize("radius", [6.0, 12.0])
def test_every_vertex_lies_near_a_place_in_position_and_normal(shapes, radius):
    """For touches of 6 and 12 mm radius and any order of the vertices (a touch's curvature order,
    here seeded permutations), every vertex lies within a cell's diagonal of a place whose fitted
    normal is within 1.5 x the screen's angle of its own (a direction bin's span); a smooth sphere
    takes no more places than cells."""
    step, angle = 0.17, 20.0
    size = step * radius
    for k, model in enumerate(shapes):
        order = np.random.default_rng(k).permutation(len(model.vertices))
        places = screen_places(model, order, radius, step=step, angle=angle)
        normals = model.fine_curvatures.normal
        pairs = cKDTree(model.vertices).sparse_distance_matrix(cKDTree(model.vertices[places]), np.sqrt(3) * size,
                                                              output_type="coo_matrix")
        cos = np.full(len(model.vertices), -1.0)
        np.maximum.at(cos, pairs.row, np.sum(normals[pairs.row] * normals[places][pairs.col], axis=1))
        gap = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        assert np.max(gap) <= 1.5 * angle, (model.name, float(np.max(gap)))
        if model.name == "sphere":
            cells = len(mesh_fast.first_per_cell(model, order, size))
            assert len(places) <= cells


def _folded_sites(model, rng):
    """The vertices of ``model`` in a seeded order that have a vertex within 2 mm whose fitted
    normal lies more than 60 degrees off their own: an edge, a rim or the side of a thin part."""
    normals = model.fine_curvatures.normal
    tree = cKDTree(model.vertices)
    for v in rng.permutation(len(model.vertices)):
        near = tree.query_ball_point(model.vertices[v], 2.0)
        if np.min(normals[near] @ normals[v]) < 0.5:
            yield int(v)


@pytest.mark.slow
def test_touches_wrapping_thin_parts_and_edges_end_on_a_fit():
    """20 noise-free P3 touches (24 mm curves, seeded) at the edges and rims of a 2 mm plate, a 2.5
    mm disc, a 3 mm fin and a block, recognised among the four: every one is right, and at least
    19 end on a pose within the fit limit (with one place a grid cell, 18 did)."""
    from tactrec.probability import fit_limit
    from tactrec.recognition import FLOOR, ModelEntry, Recognizer
    from tactrec.simulation import simulate_touch
    from tactrec.tables import CurvatureTable

    shapes = {"plate": trimesh.creation.box((40.0, 30.0, 2.0)),
              "disc": trimesh.creation.cylinder(radius=20.0, height=2.5, sections=128),
              "fin": trimesh.creation.box((30.0, 3.0, 24.0)),
              "block": trimesh.creation.box((40.0, 30.0, 20.0))}
    entries = []
    for name, tm in shapes.items():
        v, f = trimesh.remesh.subdivide_to_size(tm.vertices, tm.faces, max_edge=1.0)
        tm = trimesh.Trimesh(v, f, process=True)
        model = MeshModel(tm.vertices, tm.faces, name=name, units="mm")
        entries.append(ModelEntry(model, CurvatureTable(model.table_samples())))
    right = fits = touches = 0
    with Recognizer(entries) as recognizer:
        for m, entry in enumerate(entries):
            taken = 0
            for i, v in enumerate(_folded_sites(entry.model, np.random.default_rng(m))):
                if taken == 5:
                    break
                try:
                    data = simulate_touch(entry.model, [v], points=81, spacing=0.3, angle=60.0,
                                          rng=np.random.default_rng([m, i]))
                except ValueError:             # the curves leave the mesh
                    continue
                taken += 1
                found = recognizer.recognize(data)
                r = found.registration
                right += found.best == entry.name
                fits += bool(r.error / r.scale <= fit_limit(found.touch, FLOOR))
            touches += taken
    assert touches == 20
    assert right == 20
    assert fits >= 19


@pytest.mark.parametrize("count", [1, 24, 500])
def test_the_start_of_the_places_is_the_places_of_the_full_order(shapes, count):
    """A tier that takes the first places of the curvature order gets the same places, in the same
    order, as thinning the whole order would give, also where many gaps tie (here a few distinct
    values on a block, whose faces' curvatures are all alike), and for the cells of the frames' tiers
    as for the field screen's places."""
    rng = np.random.default_rng(5)
    for model in shapes:
        for gaps in (rng.random(len(model.vertices)), rng.integers(0, 4, len(model.vertices)).astype(float)):
            for thin in (lambda o: mesh_fast.first_per_cell(model, o, 3.0),
                         lambda o: screen_places(model, o, 12.0, step=0.17, angle=20.0)):
                whole = thin(stable_order(gaps))
                for wanted in (count, len(whole)):            # all of them: the start doubles until it has them
                    start = mesh_fast.leading_places(gaps, wanted, thin)
                    assert len(start) >= min(wanted, len(whole))
                    assert np.array_equal(start, whole[:len(start)])
            head = stable_prefix(gaps, count)
            assert len(head) >= count and np.array_equal(head, stable_order(gaps)[:len(head)])


def test_a_touchs_places_are_kept_and_extended_as_a_fresh_search_gives_them():
    """A search's places for one touch, taken a tier at a time (the first 24, then all), are those a
    fresh search takes at once, for the field screen's places, the frames' cells and every vertex;
    the folded places come whole whatever a tier asks for."""
    from tactrec.features import Touch
    from tactrec.methods.fast import FastConfig
    from tactrec.methods.fast_stages import ranked_places
    from tactrec.runner import Held
    from tactrec.simulation import simulate_random_touch

    from conftest import small_meshes

    entries = small_meshes()[:1]
    model, config = entries[0].model, FastConfig()
    data = simulate_random_touch(model, rng=np.random.default_rng(3), points=41, spacing=0.3, angle=60.0)
    touch = Touch.from_data(data)
    seen, view, g = touch.searched(model, 1)
    shared = Held(entries)
    for kind in ("screen", "cells", "every", "folded"):
        first = ranked_places(shared, 0, seen, view, g, 1, config, kind, 24)
        whole = ranked_places(shared, 0, seen, view, g, 1, config, kind, None)
        fresh = ranked_places(Held(entries), 0, seen, view, g, 1, config, kind, None)
        np.testing.assert_array_equal(whole, fresh)
        np.testing.assert_array_equal(first, whole[:len(first)])
        if kind == "folded":
            np.testing.assert_array_equal(first, whole)
        else:
            assert len(first) >= min(24, len(whole))
    assert len(ranked_places(shared, 0, seen, view, g, 1, config, "every", None)) == len(model.vertices)
