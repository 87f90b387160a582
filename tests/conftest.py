"""The fixtures the test files share: model sets built once per test process, and what each mesh
builds of itself (fields, table rows, rings) built once per test run."""

import dataclasses
import hashlib
import os
import warnings

import numpy as np
import pytest

from tactrec.database import build_entries


def pytest_configure(config):
    """Compile the kernels once, here, before pytest-xdist starts its workers: on a fresh checkout each
    worker, and each recognizer's processes forked before their first search, would otherwise compile
    the same kernels at the same time; numba's cache on disk then serves every process (a second
    or so where it is already filled)."""
    if hasattr(config, "workerinput"):                 # a worker: the controller compiled them
        return
    import trimesh

    from tactrec.engine.kernels import warm
    from tactrec.surfaces.mesh import MeshModel

    warm()                                              # the search's kernels
    ball = trimesh.creation.icosphere(subdivisions=2, radius=10.0)
    model = MeshModel(ball.vertices, ball.faces, name="ball", units="mm")
    model.distance_field, model.place_rings, model.table_samples()   # the field's, the rings' and the table's


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
def _meshes_built_once(tmp_path_factory, request):
    """What a mesh model builds of itself (its distance field, its curvature field, its lookup table's
    rows and its places' rings) is built once per run of the suite: many test files search the same
    YCB scans, each building its own models (and databases), and these builds are a large part of
    that.  The first build for a mesh (its arrays and the build's arguments) is kept in the run's
    temporary folder, which the run's worker processes share, and later builds read it.  A new run
    builds everything again, so each BLAS kernel's run builds its own."""
    from tactrec.surfaces import mesh, mesh_rings, mesh_table
    from tactrec.surfaces.base import TableSamples
    from tactrec.surfaces.mesh_curvature import CurvatureField
    from tactrec.surfaces.mesh_field import DistanceField

    run = tmp_path_factory.getbasetemp()
    worker = getattr(request.config, "workerinput", None)           # pytest-xdist's, in its workers alone
    folder = (run if worker is None else run.parent) / "meshes"
    folder.mkdir(exist_ok=True)

    def once(kind, arrays, options, build, to_store, from_store):
        digest = hashlib.sha256(kind.encode())
        for a in arrays:
            digest.update(np.ascontiguousarray(a).tobytes())
        digest.update(repr(sorted(options.items())).encode())
        path = folder / f"{kind}-{digest.hexdigest()}.npz"
        if path.exists():
            with np.load(path, allow_pickle=False) as stored:
                return from_store(stored)
        built = build()
        part = folder / f"{path.stem}.{os.getpid()}.part.npz"
        np.savez(part, **to_store(built))
        os.replace(part, path)
        return built

    field, curvatures = mesh.build_field, mesh.curvature_field
    rings, table = mesh_rings.model_rings, mesh_table.table_samples

    def built_field(vertices, faces, **options):
        return once("field", (vertices, faces), options, lambda: field(vertices, faces, **options),
                    lambda f: f.to_store(), DistanceField.from_store)

    def built_curvatures(vertices, normals, tree, frames, **options):
        return once("curvatures", (vertices, normals, frames), options,
                    lambda: curvatures(vertices, normals, tree, frames, **options), lambda f: f._asdict(),
                    lambda a: CurvatureField(*(np.array(a[k]) for k in CurvatureField._fields[:4]), float(a["radius"])))

    def built_rings(model):
        return once("rings", (model.vertices, model.faces), {"units": model.units}, lambda: rings(model),
                    lambda r: r.to_store(), lambda a: mesh_rings.PlaceRings.from_store(a, len(model.vertices)))

    def built_table(model, *, rng=0):
        if not isinstance(rng, int):
            return table(model, rng=rng)
        fields = [f.name for f in dataclasses.fields(TableSamples)]
        return once("table", (model.vertices, model.faces), {"rng": rng}, lambda: table(model, rng=rng),
                    lambda t: {k: getattr(t, k) for k in fields},
                    lambda a: TableSamples(*(np.array(a[k]) for k in fields)))

    patch = pytest.MonkeyPatch()
    patch.setattr(mesh, "build_field", built_field)
    patch.setattr(mesh, "curvature_field", built_curvatures)
    patch.setattr(mesh_rings, "model_rings", built_rings)
    patch.setattr(mesh_table, "table_samples", built_table)
    yield
    patch.undo()
