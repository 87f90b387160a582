"""The fixtures the test files share: model sets built once per test process, and each mesh's distance
field built once per test run."""

import hashlib
import os
import warnings

import numpy as np
import pytest

from tactrec.database import build_entries


@pytest.fixture(scope="session")
def table1():
    """The four surfaces of paper Table 1 with their lookup tables."""
    return build_entries(["paper-table1"])


@pytest.fixture(scope="session")
def scans():
    """Four YCB scans (banana, mug, pear, hammer) with their lookup tables."""
    return build_entries(["banana", "mug", "pear", "hammer"])


def small_meshes(*, coarse: bool = False):
    """Four small meshes (mm) of distinct shapes, for searches every vertex of which is affordable:
    an egg (an ellipsoid), a capsule, a brick and a ring (a torus), with their lookup tables;
    ``coarse``: about a third of the vertices (edges of 4-5 mm), for a search of every vertex at
    every turn."""
    import trimesh

    from tactrec.recognition import ModelEntry
    from tactrec.surfaces.mesh import MeshModel
    from tactrec.tables import CurvatureTable

    brick = trimesh.creation.box(extents=(40.0, 30.0, 20.0))
    for _ in range(3 if coarse else 4):
        brick = brick.subdivide()
    shapes = {
        "egg": trimesh.creation.icosphere(subdivisions=3 if coarse else 4, radius=1.0).apply_scale([30.0, 24.0, 18.0]),
        "capsule": trimesh.creation.capsule(height=40.0, radius=12.0, count=[24, 24] if coarse else [40, 40]),
        "brick": brick,
        "ring": trimesh.creation.torus(major_radius=22.0, minor_radius=8.0, major_sections=48 if coarse else 72,
                                       minor_sections=20 if coarse else 32),
    }
    out = []
    for name, mesh in shapes.items():
        model = MeshModel(mesh.vertices, mesh.faces, name=name, units="mm")
        out.append(ModelEntry(model, CurvatureTable(model.table_samples())))
    return out


@pytest.fixture(scope="session")
def small():
    """:func:`small_meshes`, built once."""
    return small_meshes()


@pytest.fixture(autouse=True)
def _quiet_numpy():
    with warnings.catch_warnings():
        warnings.simplefilter("error", category=DeprecationWarning)
        with np.errstate(all="warn"):
            yield


@pytest.fixture(scope="session", autouse=True)
def _fields_built_once(tmp_path_factory, request):
    """A mesh's distance field is built once per run of the suite: many test files search the same YCB
    scans, each building its own models (and databases), and a field's build is a large part of
    that.  The first build of a mesh (its vertices, faces and the build's arguments) is kept in the
    run's temporary folder, which the run's worker processes share, and later builds read it.  A new
    run builds every field again, so each BLAS kernel's run builds its own."""
    from tactrec.surfaces import mesh
    from tactrec.surfaces.mesh_field import DistanceField

    run = tmp_path_factory.getbasetemp()
    worker = getattr(request.config, "workerinput", None)           # pytest-xdist's, in its workers alone
    folder = (run if worker is None else run.parent) / "fields"
    folder.mkdir(exist_ok=True)
    build = mesh.build_field

    def built_once(vertices, faces, **options):
        digest = hashlib.sha256(np.ascontiguousarray(vertices, dtype=np.float64).tobytes())
        digest.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
        digest.update(repr(sorted(options.items())).encode())
        path = folder / f"{digest.hexdigest()}.npz"
        if path.exists():
            with np.load(path, allow_pickle=False) as arrays:
                return DistanceField.from_store(arrays)
        field = build(vertices, faces, **options)
        part = folder / f"{path.stem}.{os.getpid()}.part.npz"
        np.savez(part, **field.to_store())
        os.replace(part, path)
        return field

    patch = pytest.MonkeyPatch()
    patch.setattr(mesh, "build_field", built_once)
    yield
    patch.undo()
