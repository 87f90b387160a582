"""The command line end to end: simulate, build, recognize, demo, and the database."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tactrec.cli import main
from tactrec.database import load_database

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.mark.slow
def test_user_surfaces_end_to_end(tmp_path, capsys):
    """Two surfaces that are not built in (TOML files) work with the built-ins: simulate, build, recognize."""
    torus, hyper = EXAMPLES / "torus.toml", EXAMPLES / "hyperboloid.toml"
    t1, t2, t3 = tmp_path / "torus.json", tmp_path / "hyper.csv", tmp_path / "trough.json"
    assert main(["simulate", str(torus), "--out", str(t1), "--uv", "0.5,2.0", "--spacing", "0.01",
                 "--noise", "0.0005", "--seed", "1", "--quiet"]) == 0
    assert main(["simulate", str(hyper), "--out", str(t2), "--uv", "1.0,0.3", "--spacing", "0.02",
                 "--noise", "0.001", "--seed", "2", "--no-outward", "--quiet"]) == 0
    assert main(["simulate", "crossed-trough", "--out", str(t3), "--at", "0.4,0.3,0.0144", "--spacing", "0.02",
                 "--noise", "0.001", "--seed", "3", "--quiet"]) == 0
    db = tmp_path / "db"
    assert main(["build", "paper-table1", str(torus), str(hyper), "--out", str(db), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["recognize", str(t1), str(t2), str(t3), "--db", str(db), "--json"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    results = [json.loads(line) for line in lines]
    assert [r["file"] for r in results] == [str(t1), str(t2), str(t3)]
    assert [r["best"] for r in results] == ["torus", "hyperboloid", "crossed-trough"]
    truth = json.loads(t1.read_text())["truth"]
    best = results[0]["ranking"][0]
    # the torus is symmetric about z: compare the location's distance from the axis and height
    loc, true = np.array(best["location"]), np.array(truth["contact"])
    assert abs(np.hypot(*loc[:2]) - np.hypot(*true[:2])) < 0.02 and abs(abs(loc[2]) - abs(true[2])) < 0.02


def test_build_reuses_unchanged_and_rebuilds_changed(tmp_path, capsys):
    src = tmp_path / "hyperboloid.toml"
    shutil.copy(EXAMPLES / "hyperboloid.toml", src)
    db = tmp_path / "db"
    assert main(["build", "monkey-saddle", str(src), "--out", str(db)]) == 0
    assert "2 built, 0 unchanged" in capsys.readouterr().out
    assert main(["build", "monkey-saddle", str(src), "--out", str(db)]) == 0
    assert "0 built, 2 unchanged" in capsys.readouterr().out
    before = json.loads((db / "index.json").read_text())
    src.write_text(src.read_text().replace("b = 0.7", "b = 0.75"))
    assert main(["build", "monkey-saddle", str(src), "--out", str(db)]) == 0
    out = capsys.readouterr().out
    assert "1 built, 1 unchanged" in out and "built    hyperboloid" in out
    after = json.loads((db / "index.json").read_text())
    old = {m["name"]: m for m in before["models"]}
    new = {m["name"]: m for m in after["models"]}
    assert old["monkey-saddle"]["file"] == new["monkey-saddle"]["file"]
    assert old["hyperboloid"]["source_sha256"] != new["hyperboloid"]["source_sha256"]
    assert sorted(p.name for p in db.glob("*.npz")) == sorted(m["file"] for m in after["models"])
    loaded = load_database(db)
    assert np.isclose(loaded.get("hyperboloid").model.parameters["b"], 0.75)


def test_a_stopped_build_is_not_a_database_and_the_next_build_finishes_it(tmp_path, capsys, monkeypatch):
    """A build stopped after two of four models leaves an index that refuses to load (one line, exit 2)
    and keeps those two for the next build, which builds only the other two and writes what a build in
    one go writes."""
    import tactrec.database as database

    names = ["monkey-saddle", "crossed-trough", "ellipsoid", "elliptic-paraboloid"]
    whole = tmp_path / "whole"
    assert main(["build", *names, "--out", str(whole), "--quiet"]) == 0
    stored, calls = database._stored_blob, []

    def stopped(model, tips=()):
        calls.append(model.name)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return stored(model, tips)

    monkeypatch.setattr(database, "_stored_blob", stopped)
    monkeypatch.setattr(database.os, "cpu_count", lambda: 1)
    monkeypatch.setattr(database, "INDEX_EVERY", 0.0)
    db = tmp_path / "db"
    assert main(["build", *names, "--out", str(db), "--quiet"]) == 130
    capsys.readouterr()
    touch = tmp_path / "t.json"
    assert main(["simulate", "ellipsoid", "--out", str(touch), "--seed", "1", "--quiet"]) == 0
    assert main(["recognize", str(touch), "--db", str(db)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "stopped before it ended" in err[0] and str(db) in err[0]
    monkeypatch.setattr(database, "_stored_blob", stored)
    assert main(["build", *names, "--out", str(db)]) == 0
    assert "2 built, 2 unchanged" in capsys.readouterr().out
    assert json.loads((db / "index.json").read_text()) == json.loads((whole / "index.json").read_text())
    assert sorted(p.name for p in db.glob("*.npz")) == sorted(p.name for p in whole.glob("*.npz"))
    assert all((db / p.name).read_bytes() == p.read_bytes() for p in whole.glob("*.npz"))


def test_changed_source_is_reported_when_the_database_is_used(tmp_path, capsys):
    src = tmp_path / "hyperboloid.toml"
    shutil.copy(EXAMPLES / "hyperboloid.toml", src)
    db = tmp_path / "db"
    touch = tmp_path / "t.json"
    assert main(["build", str(src), "--out", str(db), "--quiet"]) == 0
    assert main(["simulate", str(src), "--out", str(touch), "--uv", "1,0.2", "--spacing", "0.02", "--quiet"]) == 0
    src.write_text(src.read_text() + "\n# edited\n")
    capsys.readouterr()
    assert main(["recognize", str(touch), "--db", str(db)]) == 0
    captured = capsys.readouterr()
    assert "changed since the database was built" in captured.err and "hyperboloid" in captured.out


def test_recognize_with_models_matches_db(tmp_path, capsys):
    touch = tmp_path / "t.json"
    assert main(["simulate", "monkey-saddle", "--out", str(touch), "--uv=-0.2,0.3", "--spacing", "0.02",
                 "--noise", "0.001", "--quiet"]) == 0
    db = tmp_path / "db"
    assert main(["build", "monkey-saddle", "crossed-trough", "--out", str(db), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["recognize", str(touch), "--db", str(db), "--json"]) == 0
    a = json.loads(capsys.readouterr().out)
    assert main(["recognize", str(touch), "--models", "monkey-saddle", "crossed-trough", "--json"]) == 0
    b = json.loads(capsys.readouterr().out)
    assert a["best"] == b["best"] == "monkey-saddle"
    assert np.isclose(a["ranking"][0]["error"], b["ranking"][0]["error"])
    assert main(["recognize", str(touch), "--db", str(db)]) == 0
    assert "best monkey-saddle" in capsys.readouterr().out


def test_simulated_file_holds_a_valid_touch_in_the_sensor_frame(tmp_path):
    out = tmp_path / "t.json"
    assert main(["simulate", "ellipsoid", "--out", str(out), "--uv", "1.0,1.0", "--points", "21",
                 "--spacing", "0.02", "--seed", "4", "--quiet"]) == 0
    data = json.loads(out.read_text())
    truth = data["truth"]
    R, t = np.array(truth["rotation"]), np.array(truth["translation"])
    assert not np.allclose(R, np.eye(3))
    curves = [np.array(c) for c in data["curves"]]
    assert len(curves) == 3 and all(len(c) == 21 for c in curves)
    assert np.allclose(curves[0][10] @ R.T + t, truth["contact"])


@pytest.mark.slow
def test_demo_prints_a_correct_recognition_and_writes_a_picture(tmp_path, capsys):
    """The demo writes its picture and, beside it, the 3-D page, and prints both paths."""
    picture = tmp_path / "demo.png"
    assert main(["demo", "--seed", "1", "--out", str(picture)]) == 0
    out = capsys.readouterr().out
    assert "(correct)" in out and "ranking:" in out
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    page = tmp_path / "demo.html"
    assert f"wrote {picture}" in out and f"wrote {page}" in out
    assert page.read_text(encoding="utf-8").startswith("<!DOCTYPE html>")


def test_bench_paper_example_runs_and_writes_its_table(tmp_path, capsys):
    assert main(["bench", "paper-example", "--instances", "2", "--out", str(tmp_path), "--quiet"]) == 0
    table = json.loads((tmp_path / "paper-example.json").read_text())
    noise_free = [r for r in table["rows"] if r["noise"] == 0 and r["spacing"] == 0.005][0]
    assert max(noise_free["max"]) < 1e-3
    assert "Section 4.3.1" in capsys.readouterr().out


def test_bench_paper_table4_reports_every_model(tmp_path):
    """Every scan asked for gets its row (sampled vertices, times) beside the paper's models; three of
    the ten here, since the paper's sampling takes seconds a scan (the command runs all ten)."""
    from tactrec.bench.paper_mesh import run_table4

    chosen = ("banana", "mug", "power_drill")
    table = run_table4(out=tmp_path, quiet=True, models=chosen)
    saved = json.loads((tmp_path / "paper-table4.json").read_text())
    assert tuple(saved["models"]) == chosen and all(r["sample_vertices"] > 20 for r in saved["models"].values())
    assert all(name in table["text"] for name in chosen) and "Elephant" in saved["paper"]["models"]


@pytest.mark.slow
def test_bench_paper_fig11_shares_walks_across_deltas(tmp_path):
    from tactrec.bench.paper_fig11 import run_fig11

    table = run_fig11(out=tmp_path, instances=1, jobs=1, quiet=True, models=("apple",),
                      sweeps={"delta": [0.01, 0.03], "length": [24.0], "angle": [60.0]})
    record = table["records"][0]["results"]
    small, large = record["0.01"], record["0.03"]
    assert small["candidates"]["apple"] <= large["candidates"]["apple"] and small["seconds"] <= large["seconds"]
    assert large["correct"] and (tmp_path / "paper-fig11.json").exists() and (tmp_path / "paper-fig11.png").exists()


@pytest.mark.slow
def test_closed_form_and_ycb_database_built_once_used_and_updated(tmp_path, capsys):
    """All closed-form built-ins plus four YCB scans (as files, in metres) in one
    database: built once, used by ``recognize --db`` on many touches, and after one
    scan changes only that scan is rebuilt."""
    import trimesh

    from tactrec.surfaces import BUILTIN_SETS, builtin_path

    scans = []
    for name in ("banana", "apple", "pear", "mug"):
        scans.append(tmp_path / f"{name}.stl")
        shutil.copy(builtin_path(name), scans[-1])
    db = tmp_path / "db"
    assert main(["build", "closed-form", *map(str, scans), "--units", "m", "--out", str(db)]) == 0
    assert "12 built, 0 unchanged" in capsys.readouterr().out
    touches = []
    for k, name in enumerate(BUILTIN_SETS["paper-table1"]):
        touches.append(tmp_path / f"touch-{name}.json")
        assert main(["simulate", name, "--out", str(touches[-1]), "--spacing", "0.02", "--noise", "0.0005",
                     "--seed", str(k), "--quiet"]) == 0
    for scan, vertex in ((scans[0], 1580), (scans[3], 3475)):                      # banana, mug
        # P3 settings in the scans' units: 81 points 0.3 mm apart
        touches.append(tmp_path / f"touch-{scan.stem}.json")
        assert main(["simulate", str(scan), "--units", "m", "--vertex", str(vertex), "--points", "81",
                     "--spacing", "0.0003", "--out", str(touches[-1]), "--seed", "1", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["recognize", *map(str, touches), "--db", str(db), "--json"]) == 0
    results = [json.loads(line) for line in capsys.readouterr().out.strip().splitlines()]
    assert [r["file"] for r in results] == list(map(str, touches))
    for r, t in zip(results, touches):
        assert len(r["ranking"]) == 12
        assert r["best"] == t.stem.removeprefix("touch-")
    # the meshes are in metres: the default lookup tolerance is the paper's 0.03 /mm = 30 /m
    assert all(r["ranking"][0]["candidates"] > 0 for r in results[-2:])
    # one scan changes (same shape written as ASCII STL): only it is rebuilt
    changed = trimesh.load(scans[2], force="mesh")
    changed.export(scans[2], file_type="stl_ascii")
    assert main(["build", "closed-form", *map(str, scans), "--units", "m", "--out", str(db)]) == 0
    out = capsys.readouterr().out
    assert "1 built, 11 unchanged" in out and f"built    {scans[2].stem}" in out


def test_bench_paper_table5_fills_every_cell_and_tells_the_sphere_apart(tmp_path):
    """Table 5's bookkeeping, one touch per object and spacing: every cell has the paper's value
    beside ours, and at 0.5 mm the sphere (doubly curved) is told from the three cylinders."""
    from tactrec.bench import paper_table5

    table = paper_table5.run(out=tmp_path, instances=1, quiet=True)
    assert set(table["errors"]) == {"0.05", "0.5"}
    for d in table["errors"].values():
        for method in ("paper", "fast"):
            assert set(d[method]) == set(table["objects"])
    got = table["recognised"]["0.5"]
    assert got["paper"]["sphere-33"] == got["fast"]["sphere-33"] == 1
    assert "| sphere-33 |" in (tmp_path / "paper-table5.md").read_text()
    for d, by_method in table["misses"].items():      # every miss is classified, once
        for method, kinds in by_method.items():
            assert sum(kinds.values()) == 4 - sum(table["recognised"][d][method].values())
            assert set(kinds) <= {"no_candidate", "within_noise", "beyond_noise"}


def test_within_noise_holds_a_right_fit_against_its_expected_error_at_about_95_percent():
    """The noise test on the data's own fit: the mean distance of a right fit under Gaussian noise
    (half-normal distances) lies within two standard errors of its expectation in about 95% of
    draws, and a fit 30% worse on 63 points is outside them in every draw."""
    from tactrec.bench.common import within_noise

    rng = np.random.default_rng(5)
    sigma, points = 0.164, 63
    expected = sigma * np.sqrt(2 / np.pi)
    fits = np.abs(rng.normal(0, sigma, (2000, points))).mean(axis=1)
    held = np.mean([within_noise(f, expected, points=points, fit=f) for f in fits])
    assert 0.92 <= held <= 0.98
    assert not any(within_noise(f, 1.3 * f, points=points, fit=f) for f in fits)


def test_bench_paper_table6_fills_the_matrix_and_counts_nc_cells(tmp_path):
    """Table 6's bookkeeping on two scans, one touch each: every cell is an error or NC, the NC
    count is the cells without one, and the paper's summary is printed beside ours."""
    from tactrec.bench import paper_table6

    table = paper_table6.run(out=tmp_path, models=("banana", "strawberry"), quiet=True)
    for method in ("paper", "fast"):
        s = table["summary"][method]
        assert set(s["errors"]) == {"banana", "strawberry"}
        assert s["nc_cells"] == sum(v is None for row in s["errors"].values() for v in row.values())
        assert all(v is None or v > 0 for row in s["errors"].values() for v in row.values())
        assert sum(s["misses"].values()) == 2 - sum(s["recognised"].values())
        assert set(s["misses"]) <= {"estimate_failed", "no_candidate", "within_noise", "outfitted", "search_miss"}
    text = (tmp_path / "paper-table6.md").read_text()
    assert "| strawberry |" in text and "the paper (its own ten objects): 10 of 10" in text


def test_bench_paper_steps_on_a_sphere_finds_every_step_sound(tmp_path):
    """The step audit on a sphere of radius 30 mm (about 1 mm edges), where every step has a known
    answer: the table's fit and the default estimate both give k1 = k2 = -1/30 /mm, so the gap is
    within delta on every touch and a row lies near it; the data normal is the vertex normal to a
    couple of degrees; eq. 15 at the touched vertex is small with either rotation scan."""
    import trimesh

    from tactrec.bench import paper_steps

    path = tmp_path / "ball.ply"
    trimesh.creation.icosphere(subdivisions=5, radius=30.0).export(path)
    table = paper_steps.run(out=tmp_path, instances=5, models=(str(path),), scans="shipped", quiet=True)
    for record in table["records"]:
        k1, k2 = record["table_at_touch"]
        assert abs(k1 + 1 / 30) < 0.003 and abs(k2 + 1 / 30) < 0.003
    s = table["readings"]["default"]
    assert s["touches"] == 5 and s["failed"] == 0
    assert s["within_delta_percent"] == 100 and s["row_near_percent"] == 100
    assert s["gap_median"] < 0.005 and s["tilt_p90_deg"] < 2.0
    assert s["error_at_touch_phi10"]["p90"] < 0.05 and s["error_at_touch_phi1"]["p90"] < 0.05
    assert "| default |" in (tmp_path / "paper-steps.md").read_text()


def test_paper_method_parabola_reading_estimates_a_sphere_and_reaches_the_benchmark(tmp_path):
    """The ``parabola_points`` reading of Section 3.1.1: on a sphere of radius 25 the parabola over
    3 points each side gives k1 = k2 = -1/25; in ``paper-fig11`` it is the estimate the lookup
    uses (the record's estimate is that reading's, not the default's), and the touch is recognised."""
    import trimesh

    from tactrec.bench.paper_fig11 import p3_touch, run_fig11
    from tactrec.estimation import estimate
    from tactrec.methods.paper import PaperConfig
    from tactrec.simulation import simulate_random_touch
    from tactrec.surfaces import load_model
    from tactrec.surfaces.mesh import MeshModel

    config = PaperConfig(parabola_points=3)
    rng = np.random.default_rng(3)
    ball = trimesh.creation.icosphere(subdivisions=6, radius=25.0)
    model = MeshModel(ball.vertices, ball.faces, name="ball", units="mm")
    for _ in range(5):
        data = simulate_random_touch(model, points=41, spacing=0.3, rng=rng)
        g = config.geometry(data)
        assert abs(g.k1 + 0.04) < 0.004 and abs(g.k2 + 0.04) < 0.004
    table = run_fig11(out=tmp_path, instances=1, jobs=1, quiet=True, models=("apple",),
                      sweeps={"delta": [0.03], "length": [24.0], "angle": [60.0]}, options={"parabola_points": 3})
    record = table["records"][0]
    _, data = p3_touch(load_model("apple"), 0, 0, seed=0, length=24.0, angle=60.0)
    assert np.allclose(record["estimate"], [config.geometry(data).k1, config.geometry(data).k2])
    assert not np.allclose(record["estimate"], [estimate(data).k1, estimate(data).k2])
    assert record["results"]["0.03"]["correct"]
    assert table["benchmark"] == "paper-fig11-parabola-points3"
    assert (tmp_path / "paper-fig11-parabola-points3.json").exists()
    # the recognition itself takes the reading: a different estimate, the same right model
    from tactrec.bench.common import scan_database
    from tactrec.recognition import recognize

    entries = scan_database(("apple", "banana")).entries
    default, reading = (recognize(data, entries, method="paper", **o) for o in ({}, {"parabola_points": 3}))
    assert default.best == reading.best == "apple"
    assert default.ranking[0].error != reading.ranking[0].error


def test_bench_help_lists_every_benchmark_with_what_it_measures(capsys):
    """``tactrec bench --help`` names every benchmark with one line, and each name runs a function; then
    ``report``."""
    from tactrec.bench import BENCHMARKS

    with pytest.raises(SystemExit) as exit_:
        main(["bench", "--help"])
    assert exit_.value.code == 0
    listing, report = capsys.readouterr().out.split("benchmarks:\n", 1)[1].split("\n\n")
    listing = listing.splitlines()
    assert [line.split()[0] for line in listing] == list(BENCHMARKS)
    assert report.split()[0] == "report" and "HTML" in report
    for line, (name, benchmark) in zip(listing, BENCHMARKS.items()):
        assert line.split(None, 1)[1] == benchmark.summary and benchmark.summary
        assert callable(benchmark.run), name
