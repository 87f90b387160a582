"""The generated catalogue: varied, closed, scan-like meshes in families of near twins, the same for a seed."""

import hashlib
import json

import numpy as np
import pytest
import trimesh

from tactrec.bench import catalogue as C
from tactrec.cli import main


def test_the_families_hold_every_body_and_feature_and_near_twins_of_each_kind():
    members = [m for index in range(48) for m in C._family(3, index)]
    assert {m["body"] for m in members} == set(C.BODIES)
    assert {f for m in members for f in m["features"]} == set(C.FEATURES)
    for a, b, c, d in zip(*(iter(members),) * 4):
        assert [m["variant"] for m in (a, b, c, d)] == list(C.VARIANTS)
        assert len({m["family"] for m in (a, b, c, d)}) == 1 and C.family_of(a["name"]) == C.family_of(d["name"])
        assert all(C.SIZE_MM[0] <= m["size_mm"] <= C.SIZE_MM[1] for m in (a, b, c, d))
        assert 1.2 <= max(a["size_mm"], b["size_mm"]) / min(a["size_mm"], b["size_mm"]) <= 1.5
        assert b["features"] == a["features"] and b["solid"] == a["solid"]
        assert c["features"] == a["features"][:-1] and d["features"][:-1] == a["features"]
        assert c["size_mm"] == d["size_mm"] == a["size_mm"]


def test_a_mesh_is_closed_scan_like_and_its_size_and_a_larger_twin_is_the_same_shape():
    a, b, c, _ = C._family(1, 2)
    mesh, twin = C.surface_mesh(a["solid"], a["size_mm"]), C.surface_mesh(b["solid"], b["size_mm"])
    for m, member in ((mesh, a), (twin, b)):
        assert m.is_watertight and m.volume > 0
        assert abs(len(m.faces) - C.FACES) <= 4
        assert np.ptp(m.vertices, axis=0).max() == pytest.approx(member["size_mm"], rel=1e-9)
    ratio = b["size_mm"] / a["size_mm"]
    np.testing.assert_allclose(twin.vertices, mesh.vertices * ratio, atol=1e-9 * b["size_mm"])
    less = C.surface_mesh(c["solid"], c["size_mm"])
    assert abs(less.area - mesh.area) > 1e-3 * mesh.area          # a feature fewer is another surface


def test_the_catalogue_has_holes_and_handles_as_well_as_solids_of_genus_zero():
    genus = [(2 - C.surface_mesh(m["solid"], 80.0).euler_number) // 2
             for m in (C._family(0, i)[0] for i in range(8))]
    assert min(genus) == 0 and max(genus) >= 1


def test_the_same_seed_writes_the_same_files_and_a_stopped_run_resumes(tmp_path, capsys):
    assert main(["catalogue", "--out", str(tmp_path / "one"), "--count", "5", "--seed", "7", "--jobs", "1",
                 "--quiet"]) == 0
    folder = tmp_path / "one" / f"v{C.VERSION}-s7"
    manifest = json.loads((folder / "catalogue.json").read_text())
    assert [m["name"] for m in manifest["models"]] == [p.stem for p in sorted(folder.glob("*.ply"))]
    assert len(manifest["models"]) == 5 and manifest["models"][4]["family"] == 1
    lost = folder / manifest["models"][2]["file"]
    lost.unlink()
    paths = C.generate(tmp_path / "one", count=5, seed=7)
    assert [hashlib.sha256(p.read_bytes()).hexdigest() for p in paths] == [m["sha256"] for m in manifest["models"]]
    other = C.generate(tmp_path / "two", count=2, seed=7)
    assert [p.read_bytes() for p in other] == [p.read_bytes() for p in paths[:2]]
    mesh = trimesh.load(paths[0], force="mesh")
    assert mesh.is_watertight


def test_the_field_read_coarsely_away_from_the_surface_meshes_as_the_exact_field_does():
    import igl

    for index in (0, 5):
        node = C._family(2, index)[0]["solid"]
        h, cells = 1.4 / 64, [C.STRIDE * 16 + 1] * 3
        lo = np.full(3, -0.7)
        points, field = C._banded(node, lo, h, cells)
        exact = C.distance(node, points)
        assert np.count_nonzero(field != exact) > 0.2 * len(field)       # most of the grid is read coarsely
        banded, full = igl.marching_cubes(field, points, *cells, 0.0), igl.marching_cubes(exact, points, *cells, 0.0)
        np.testing.assert_array_equal(banded[0], full[0])
        np.testing.assert_array_equal(banded[1], full[1])
