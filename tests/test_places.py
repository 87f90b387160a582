"""The field screen's places (tactrec.engine.screen.screen_places): every vertex of a mesh lies near
a place in position and in normal, so that some hypothesis poses the data's normal onto about the
surface's own wherever the contact lies, on a sharp edge or a thin part as on a smooth face."""

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from tactrec.engine.screen import screen_places
from tactrec.registration import mesh_fast
from tactrec.surfaces.mesh import MeshModel


def _model(tm, name):
    model = MeshModel(np.asarray(tm.vertices), np.asarray(tm.faces), name=name)
    mesh_fast.prepare(model)
    return model


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
            assert len(places) == cells
