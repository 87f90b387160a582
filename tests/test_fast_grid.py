"""The grid at the exact steps' basin (tactrec.methods.fast_stages.hop_stage): a pose the exact steps
leave a few times beyond the fit, near the truth on a finely faceted scan, is brought to the fit."""

import types

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from tactrec.features import Touch
from tactrec.methods.common import in_model_units
from tactrec.methods.fast import FastConfig
from tactrec.methods.fast_stages import hop_stage, mesh_registration
from tactrec.probability import fit_limit
from tactrec.recognition import FLOOR
from tactrec.registration import mesh_fast
from tactrec.registration.solver import Criteria, solve
from tactrec.simulation import simulate_touch, spread_vertices, truth_pose
from tactrec.surfaces.mesh import MeshModel


@pytest.fixture(scope="module")
def bumpy():
    """A sphere of 30 mm in facets of about 0.6 mm, each vertex moved 0.05 mm (sd) along its radius:
    the fine, rough facets of a scan, on which the exact steps have many shallow basins."""
    tm = trimesh.creation.icosphere(subdivisions=6, radius=30.0)
    rng = np.random.default_rng(0)
    v = np.asarray(tm.vertices) * (1 + 0.05 / 30 * rng.normal(size=(len(tm.vertices), 1)))
    model = MeshModel(v, np.asarray(tm.faces), name="bumpy")
    mesh_fast.prepare(model)
    return model


@pytest.mark.slow
def test_the_grid_brings_a_pose_the_exact_steps_left_near_the_truth_to_the_fit(bumpy):
    """Twenty seeded noise-free P3 touches, each started 8 degrees (about the contact) and 0.4 mm off
    its true pose: 40 exact steps leave at least three beyond the fit limit, and the grid about
    each such pose brings at least two thirds of them within it."""
    config = FastConfig()
    held = types.SimpleNamespace(entries=[types.SimpleNamespace(model=bumpy)])
    stalled = mended = 0
    for i, vertex in enumerate(spread_vertices(bumpy, 20, rings=15, rng=np.random.default_rng(1))[:20]):
        data = simulate_touch(bumpy, [int(vertex)], points=81, spacing=0.3, angle=60.0, rng=np.random.default_rng(i))
        touch = Touch.from_data(data)
        t = in_model_units(touch, bumpy)
        R0, t0 = truth_pose(data)
        rng = np.random.default_rng([7, i])
        axis = rng.normal(size=3)
        turn = Rotation.from_rotvec(np.radians(8.0) * axis / np.linalg.norm(axis)).as_matrix()
        contact = R0 @ t.geometry.contact + t0
        shift = rng.normal(size=3)
        start_t = turn @ (t0 - contact) + contact + 0.4 * shift / np.linalg.norm(shift)
        R, tr, error, _ = solve(t.exact(bumpy), (turn @ R0)[None], start_t[None], t.joint_points,
                                Criteria(40, history=3))
        limit = fit_limit(touch, FLOOR)
        if error[0] <= limit:
            continue
        stalled += 1
        start = mesh_registration(bumpy, t, R[0], tr[0], error[0], 1)
        found = hop_stage(held, [0], touch, config, items=[(start, 1.0)])
        r = found[0].registration
        mended += r.error / r.scale <= limit
    assert stalled >= 3
    assert mended >= 2 * stalled / 3
