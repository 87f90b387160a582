"""Triangle-mesh models (paper Section 5): clean-up, units, curvature tables, sections."""

import json

import numpy as np
import pytest
import trimesh

from tactrec.cli import main
from tactrec.database import load_database
from tactrec.errors import InputError
from tactrec.surfaces import load_model
from tactrec.surfaces.mesh_table import sample_vertices, vertex_curvatures
from tactrec.surfaces.mesh import MeshModel
from tactrec.surfaces.mesh_cleanup import clean_mesh


def _model(tm, name="m"):
    v, f, _ = clean_mesh(np.asarray(tm.vertices, dtype=float), np.asarray(tm.faces))
    return MeshModel(v, f, name=name)


def grid_cylinder(r=15.0, h=60.0, nu=192, nv=80):
    """An open cylinder (no caps) triangulated on a parameter grid."""
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    z = np.linspace(-h / 2, h / 2, nv)
    U, Z = np.meshgrid(u, z, indexing="ij")
    V = np.stack([r * np.cos(U), r * np.sin(U), Z], -1).reshape(-1, 3)
    idx = np.arange(nu * nv).reshape(nu, nv)
    a, b = idx[:, :-1], np.roll(idx, -1, axis=0)[:, :-1]
    c, d = np.roll(idx, -1, axis=0)[:, 1:], idx[:, 1:]
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return trimesh.Trimesh(V, F, process=False)


def test_table_curvatures_within_5_percent_on_a_sphere():
    m = _model(trimesh.creation.icosphere(subdivisions=5, radius=20.0))
    tab = m.table_samples(rng=0)
    assert len(tab) > 20
    assert np.allclose(tab.k1, -1 / 20, rtol=0.05) and np.allclose(tab.k2, -1 / 20, rtol=0.05)
    assert np.all(np.sum(tab.normals * tab.positions, axis=1) > 0)          # eq. 13 normals point out


def test_table_curvatures_within_5_percent_on_an_open_cylinder():
    m = _model(grid_cylinder())
    tab = m.table_samples(rng=0)
    assert len(tab) > 20
    assert np.all(np.abs(tab.k1) < 0.05 / 15) and np.allclose(tab.k2, -1 / 15, rtol=0.05)


def test_table_curvatures_within_5_percent_on_a_torus():
    R, r = 30.0, 10.0
    m = _model(trimesh.creation.torus(major_radius=R, minor_radius=r, major_sections=256, minor_sections=96))
    tab = m.table_samples(rng=0)
    rho = np.hypot(tab.positions[:, 0], tab.positions[:, 1])
    k_around = -((rho - R) / r) / rho
    true = np.sort(np.stack([k_around, np.full(len(rho), -1 / r)], 1), axis=1)[:, ::-1]
    scale = np.max(np.abs(true), axis=1)
    assert np.all(np.abs(tab.k1 - true[:, 0]) <= 0.05 * scale) and np.all(np.abs(tab.k2 - true[:, 1]) <= 0.05 * scale)
    assert np.any(tab.k1 > 0)                                            # the saddle-shaped inner side is seen


def test_vertex_sampling_follows_the_paper_and_is_seeded():
    m = _model(trimesh.creation.icosphere(subdivisions=4, radius=20.0))
    a, b = sample_vertices(m, rng=1), sample_vertices(m, rng=1)
    assert np.array_equal(a, b) and not np.array_equal(a, sample_vertices(m, rng=2))
    # the marked neighbourhoods of different samples do not overlap: samples are > 2 rings apart
    for v in a[:20]:
        assert not set(m.ring(int(v), 2)) & (set(a.tolist()) - {int(v)})


def test_messy_scan_is_cleaned_and_reported(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.03)
    stray = trimesh.Trimesh([[1, 1, 1], [1.001, 1, 1], [1, 1.001, 1]], [[0, 1, 2]])
    mesh = trimesh.util.concatenate([sphere, stray])
    faces = np.vstack([mesh.faces, [[0, 0, 1]]])                         # a degenerate face
    path = tmp_path / "scan.stl"                                        # STL repeats every vertex per face
    trimesh.Trimesh(mesh.vertices, faces, process=False).export(path)
    m = MeshModel.from_file(path, units="m", scale=1000.0)
    rep = m.cleanup
    assert rep["duplicate_vertices_merged"] > 0 and rep["stray_components_dropped"] == 1
    assert rep["degenerate_faces_dropped"] >= 1
    assert len(m.vertices) == len(sphere.vertices) and len(m.faces) == len(sphere.faces)
    assert m.units == "mm" and np.isclose(np.linalg.norm(m.vertices, axis=1).max(), 30.0, rtol=1e-6)
    k1, k2 = vertex_curvatures(m, [0, 100])
    assert np.allclose([k1, k2], -1 / 30.0, rtol=0.05)                  # per millimetre


def test_open_mesh_file_loads_and_sections(tmp_path):
    path = tmp_path / "tube.off"
    grid_cylinder().export(path)
    m = load_model(path)
    assert m.kind == "mesh" and m.name == "tube"
    assert not trimesh.Trimesh(m.vertices, m.faces, process=False).is_watertight
    site = np.array([float(np.argmin(np.abs(m.vertices[:, 2])))])
    frame = m.site_frame(site)
    curve = m.plane_section(site, frame.d1, spacing=0.5, count=21)
    assert np.allclose(curve[10], frame.point)
    assert np.allclose(np.linalg.norm(np.diff(curve, axis=0), axis=1), 0.5, rtol=0.02)
    assert np.max(np.abs(np.hypot(curve[:, 0], curve[:, 1]) - 15.0)) < 0.01
    with pytest.raises(ValueError, match="edge of the mesh"):
        m.plane_section(site, [0, 0, 1], spacing=2.0, count=41)         # 80 mm along a 60 mm tube


@pytest.mark.parametrize("content, message", [
    (b"", "empty file"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\n", "cannot read mesh"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangles"),
    (b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "degenerate mesh"),
])
def test_broken_mesh_files_give_one_line(tmp_path, capsys, content, message):
    suffix = ".ply" if content.startswith(b"ply") else ".obj"
    path = tmp_path / f"broken{suffix}"
    path.write_bytes(content)
    assert main(["build", str(path), "--out", str(tmp_path / "db")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and message in err[0]
    assert not (tmp_path / "db" / "index.json").exists()


def test_mesh_database_records_units_and_rebuilds_on_new_options(tmp_path, capsys):
    path = tmp_path / "ball.ply"
    trimesh.creation.icosphere(subdivisions=3, radius=0.02).export(path)
    db = tmp_path / "db"
    assert main(["build", str(path), "sphere-33", "--out", str(db), "--units", "m", "--scale", "1000"]) == 0
    index = json.loads((db / "index.json").read_text())
    entry = next(m for m in index["models"] if m["name"] == "ball")
    assert entry["kind"] == "mesh" and entry["units"] == "mm" and entry["options"] == {"units": "m", "scale": 1000.0}
    loaded = load_database(db).get("ball")
    assert loaded.model.units == "mm" and np.isclose(np.linalg.norm(loaded.model.vertices, axis=1).max(), 20.0)
    assert len(loaded.table) > 0 and np.allclose(loaded.table.samples.k2, -1 / 20, rtol=0.1)
    capsys.readouterr()
    assert main(["build", str(path), "sphere-33", "--out", str(db), "--units", "m", "--scale", "1000"]) == 0
    assert "0 built, 2 unchanged" in capsys.readouterr().out
    assert main(["build", str(path), "sphere-33", "--out", str(db), "--units", "m"]) == 0
    assert "1 built, 1 unchanged" in capsys.readouterr().out


def test_unknown_units_for_a_mesh(tmp_path):
    path = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=2).export(path)
    with pytest.raises(InputError, match="unknown units"):
        MeshModel.from_file(path, units="furlong")


def test_exact_distance_and_locate_on_a_mesh():
    m = _model(trimesh.creation.icosphere(subdivisions=4, radius=20.0))
    pts = np.array([[0.0, 0.0, 30.0], [5.0, -3.0, 1.0]])
    d = m.distance(pts)
    assert np.allclose(d, np.abs(np.linalg.norm(pts, axis=1) - 20.0), atol=0.05)
    site = m.locate([0.0, 0.0, 30.0])
    frame = m.site_frame(site)
    assert len(site) == 3 and np.allclose(frame.point / 20.0, [0, 0, 1], atol=0.01)


def test_ycb_scans_are_built_in_and_read_in_millimetres():
    from tactrec.surfaces import BUILTIN_SETS, builtin_names

    names = set(builtin_names())
    assert set(BUILTIN_SETS["paper-fig11"]) <= names and len([n for n in names if "-" not in n or n.startswith("cups")]) > 60
    banana = load_model("banana")
    assert banana.kind == "mesh" and banana.units == "mm" and 150 < banana.size < 300


def test_an_unknown_method_or_option_is_a_clear_error():
    from tactrec.methods import get_method

    assert get_method("paper").name == "paper"
    with pytest.raises(InputError, match="unknown method"):
        get_method("nonesuch")
    with pytest.raises(InputError, match="has no option 'delat' \\(did you mean 'delta'\\?\\)"):
        get_method("paper").configure(delat=0.1)
    with pytest.raises(InputError, match="delta must be positive"):
        get_method("paper").configure(delta=-1.0)
    with pytest.raises(InputError, match="has no option 'delta'"):
        get_method("fast").configure(delta=0.1)
    with pytest.raises(InputError, match="budget must be"):
        get_method("fast").configure(budget=0)


def test_touch_anywhere_on_a_face_of_a_scan(tmp_path):
    """Sections through a point inside a face (not a vertex), P3's length and spacing."""
    from tactrec.simulation import simulate_touch

    mug = load_model("mug")
    site = mug.locate([0.0, 0.0, 0.0])
    touch = simulate_touch(mug, site, points=81, spacing=0.3, noise=0.0, sensor_frame=False, rng=0)
    truth = touch.meta["truth"]
    for c in touch.curves:
        assert np.allclose(c[40], truth["contact"])
        assert np.max(mug.distance(c)) < 1e-6
        assert np.allclose(np.linalg.norm(np.diff(c, axis=0), axis=1), 0.3, atol=0.02)


@pytest.mark.slow
def test_paper_mesh_registration_walks_to_the_touched_vertex():
    """Section 5.3: E(v) (eq. 15) is ~0 at the true vertex and the greedy 1-ring walk reaches it."""
    from tactrec.estimation import estimate
    from tactrec.registration import mesh_paper
    from tactrec.simulation import simulate_touch

    m = load_model("banana")
    v = 1580
    touch = simulate_touch(m, [v], points=41, spacing=0.3, angle=60.0, rng=0)
    geom = estimate(touch)
    problem = mesh_paper.MeshSuperposition(m, geom, touch.curves, phi_step=10.0)
    e_true, _ = problem.error(v)
    assert e_true < 0.05                                   # mm; the phi grid is 10 degrees
    start = int(m.rings(v, 3)[3][0])
    end, e, phi = problem.walk(start, max_steps=50)
    assert e <= e_true + 1e-9 and np.linalg.norm(m.vertices[end] - m.vertices[v]) < 2 * m.mean_edge
    # the whole registration from a one-row table at the start vertex: pose maps the data onto the mesh
    from tactrec.surfaces.base import TableSamples
    from tactrec.tables import CurvatureTable

    row = TableSamples(np.array([[float(start)]]), m.vertices[[start]], m.vertex_normals[[start]],
                       np.array([geom.k1]), np.array([geom.k2]))
    reg = mesh_paper.register(m, CurvatureTable(row), geom, touch.points, curves=touch.curves)
    assert reg.ok and reg.candidates == 1 and np.isclose(reg.error, e)
    mapped = touch.points @ reg.rotation.T + reg.translation
    assert np.mean(m.distance(mapped)) < 0.05


def test_p3_contacts_are_at_least_15_rings_apart():
    from tactrec.simulation import spread_vertices

    m = load_model("apple")
    chosen = spread_vertices(m, 10, rings=15, rng=3)
    assert len(chosen) == 10 and np.array_equal(chosen, spread_vertices(m, 10, rings=15, rng=3))
    for v in chosen:
        near = set(m.ring(int(v), 15).tolist())
        assert not near & (set(chosen.tolist()) - {int(v)})


def _reference_error(m, problem, v, phi):
    """Eq. 15 the slow, obvious way: trimesh's plane-mesh intersection segments,
    chained into polylines, the one through the anchor resampled at the offsets."""
    import trimesh

    from tactrec.surfaces.mesh_sections import resample_polyline

    tm = trimesh.Trimesh(m.vertices, m.faces, process=False)
    F = m.vertex_frames([v])[0]
    c, s = np.cos(phi), np.sin(phi)
    M = F @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    q = m.vertices[v]
    total, count = 0.0, 0
    for i in range(problem.ncurves):
        x = problem.points[0][problem.point_curve == i]            # phi = 0: the data curve, local frame
        off = problem.point_offset[problem.point_curve == i]
        pts = x @ M.T + q
        centre = pts.mean(axis=0)
        _, _, vt = np.linalg.svd(pts - centre)
        normal, along = vt[2], (vt[0] if (pts[-1] - pts[0]) @ vt[0] >= 0 else -vt[0])
        anchor = q - ((q - centre) @ normal) * normal
        segs = trimesh.intersections.mesh_plane(tm, normal, centre)
        # chain segments into the polyline through the anchor
        key = lambda p: tuple(np.round(p, 9))
        ends = {}
        for k, (a, b) in enumerate(segs):
            ends.setdefault(key(a), []).append((k, 1))
            ends.setdefault(key(b), []).append((k, 0))
        mids = segs.mean(axis=1)
        start = int(np.argmin(np.linalg.norm(mids - anchor, axis=1)))

        seen = {start}

        def follow(k, end):
            chain = []
            while True:
                p = segs[k, end]
                chain.append(p)
                nxt = [(j, e) for j, e in ends[key(p)] if j != k]
                if not nxt or nxt[0][0] == start:
                    return chain, bool(nxt)
                k, e = nxt[0]
                seen.add(k)
                end = e
        forward, closed = follow(start, 1)
        line = np.array([segs[start, 0]] + forward) if closed else np.array(follow(start, 0)[0][::-1] + forward)
        ref = resample_polyline(line, anchor, along, off, closed=closed)
        total += float(np.sum(np.linalg.norm(pts - ref, axis=1)))
        count += len(pts)
    return total / count


def test_eq15_error_matches_a_direct_computation():
    """The batched section marching gives the same E(v, phi) as trimesh's
    plane intersection chained by hand, at vertices near and far from the touch."""
    from tactrec.estimation import estimate
    from tactrec.registration import mesh_paper
    from tactrec.simulation import simulate_touch

    m = load_model("pear")
    touch = simulate_touch(m, [2000], points=41, spacing=0.3, angle=60.0, rng=1)
    geom = estimate(touch)
    problem = mesh_paper.MeshSuperposition(m, geom, touch.curves, phi_step=30.0)
    vertices = np.array([2000, *m.rings(2000, 2)[2][:2], 100, 5000])
    E = problem._errors(vertices)                                      # (vertices, phis)
    assert E.shape == (5, 12) and np.all(np.isfinite(E))
    for a, v in enumerate(vertices):
        for b in (0, 4, 7):
            assert np.isclose(E[a, b], _reference_error(m, problem, int(v), problem.phis[b]), rtol=1e-6, atol=1e-9)
    assert E[0].min() < 0.5 * E[3:].min()                              # touched vertex vs far away


def test_face_neighbours_pair_faces_across_their_shared_edges():
    from tactrec.surfaces.mesh import MeshModel

    # a square of two triangles plus a third triangle hanging off the diagonal (a non-manifold edge)
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], dtype=float)
    faces = np.array([[0, 1, 2], [0, 2, 3], [2, 0, 4]])
    m = MeshModel(vertices, faces, name="square")
    face, edge = m.face_neighbours
    # edge k of face f joins corners k and k+1; across it lies face[f, k], whose edge edge[f, k] is the same
    for f in range(3):
        for k in range(3):
            g = face[f, k]
            if g < 0:
                continue
            assert {*faces[f, [k, (k + 1) % 3]]} == {*faces[g, [edge[f, k], (edge[f, k] + 1) % 3]]}
            assert face[g, edge[f, k]] == f
    assert face[0, 0] == -1 and face[1, 1] == -1                # the square's outer edges
    assert face[0, 2] == 1 and face[2, 0] == -1                 # the diagonal: first two faces paired


def test_paper_like_scans_are_refined_smoothly_and_scaled_into_the_papers_range():
    """Loop subdivision of a coarse sphere: more vertices, nearer the sphere than the facets were,
    scaled into 60-95 mm; an edge shared by three faces is repaired first."""
    from tactrec.surfaces.paper_like import manifold_faces, paper_like

    coarse = trimesh.creation.icosphere(subdivisions=1, radius=20.0)          # 42 vertices, 40 mm across
    m = MeshModel(coarse.vertices, coarse.faces, name="ball", units="mm")
    like = paper_like(m, vertices=600)
    assert len(like.vertices) >= 600 and like.name == "ball"
    extent = like.bounds[1] - like.bounds[0]
    assert np.isclose(extent.max(), 60.0)                                      # 40 mm -> the low end
    r = np.linalg.norm(like.vertices, axis=1)
    centroids = np.linalg.norm(like.vertices[like.faces].mean(axis=1), axis=1)
    coarse_gap = 1 - np.linalg.norm(m.vertices[m.faces].mean(axis=1), axis=1).min() / 20.0
    assert 1 - centroids.min() / r.max() < coarse_gap / 4                    # facets hug the sphere closer
    big = paper_like(MeshModel(coarse.vertices * 10, coarse.faces, name="big", units="mm"), vertices=100)
    assert np.isclose((big.bounds[1] - big.bounds[0]).max(), 95.0)             # 400 mm -> the high end
    faces = np.vstack([coarse.faces, [[coarse.faces[0, 0], coarse.faces[0, 1], 41]]])   # a third face on an edge
    assert len(manifold_faces(faces)) == len(coarse.faces)
    with pytest.raises(ValueError, match="millimetre"):
        paper_like(MeshModel(coarse.vertices, coarse.faces, name="m", units="m"))


def test_plane_sections_are_trimeshs_own_cut_without_the_blas(scans):
    """The package's plane section of a scan gives trimesh's polylines (the same pieces, the same
    points within rounding), through vertices, edges and faces alike, and None where the plane misses."""
    from tactrec.surfaces.mesh_sections import plane_section

    model = scans.get("mug").model
    mesh = trimesh.Trimesh(model.vertices, model.faces, process=False)
    rng = np.random.default_rng(8)
    for k in range(12):
        v = int(rng.integers(len(model.vertices)))
        origin = model.vertices[v] if k % 2 == 0 else model.vertices[v] + rng.normal(size=3)   # through a vertex
        normal = np.array([0.0, 0.0, 1.0]) if k % 4 == 0 else rng.normal(size=3)
        normal = normal / np.linalg.norm(normal)
        ours = plane_section(model.vertices, model.faces, origin, normal)
        theirs = mesh.section(plane_origin=origin, plane_normal=normal)
        assert len(ours.entities) == len(theirs.entities)
        for a, b in zip(ours.entities, theirs.entities):
            assert np.allclose(a.discrete(ours.vertices), b.discrete(theirs.vertices), rtol=0, atol=1e-9)
    far = model.vertices.max(axis=0) + 10.0
    assert plane_section(model.vertices, model.faces, far, np.array([1.0, 0.0, 0.0])) is None
