"""Machined parts made by code (tactrec.bench.cad_parts): closed, sharp-edged, and every noise-free
touch at their vertices ends on a pose that fits."""

import numpy as np
import pytest

from tactrec.bench.cad_parts import CAD, MAX_EDGE, part_mesh
from tactrec.bench.common import database, simulate
from tactrec.probability import fit_limit
from tactrec.recognition import FLOOR, Recognizer


def test_every_part_is_a_closed_solid_split_to_the_largest_edge():
    import trimesh

    for name in CAD:
        vertices, faces = part_mesh(name)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        assert mesh.is_watertight and mesh.volume > 0, name
        assert mesh.edges_unique_length.max() <= MAX_EDGE + 1e-9, name
        # sharp: some edges fold by a right angle or more
        assert np.degrees(mesh.face_adjacency_angles.max()) >= 60.0, name


@pytest.mark.slow
def test_noise_free_touches_of_sharp_parts_end_on_a_fit():
    """The paper's P3 (24 mm curves at vertices, no noise, sensor frame) on the ten parts, two seeded
    touches each, recognised among all ten: at least 19 of 20 end on a pose within the fit limit
    (a flat or right-angled patch fits several parts exactly, so which part is not asserted)."""
    db = database(CAD)
    fits = 0
    with Recognizer(db.entries) as recognizer:
        for m, entry in enumerate(db.entries):
            for i in range(2):
                _, data = simulate(entry, m, i, 3, "p3")
                r = recognizer.recognize(data)
                reg = r.registration
                fits += reg is not None and reg.error / reg.scale <= fit_limit(r.touch, FLOOR)
    assert fits >= 19
