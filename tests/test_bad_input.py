"""Bad input to the ``tactrec`` command.

Every kind of bad input (a data file, a model file, a database, an argument)
must give exit status 2 and exactly one line on stderr that names the
offending file (or argument) and says what is wrong: never a traceback, and
never a half-written output file.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest

from tactrec.cli import main

# ---------------------------------------------------------------------- helpers


def bad(capsys, argv, name, problem):
    """Run ``tactrec argv``; check the exit status and the one line on stderr.

    ``name`` (a file, an argument) and ``problem`` (a phrase saying what is
    wrong, compared without case) must both appear in that line.
    """
    rc = main([str(a) for a in argv])
    captured = capsys.readouterr()
    err = captured.err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, f"expected one line on stderr, got:\n{err}"
    line = lines[0]
    assert rc == 2, line
    assert line.startswith("tactrec: "), line
    assert str(name) in line, line
    assert problem.lower() in line.lower(), line
    assert captured.out == "", captured.out
    return line


def files_in(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


def simulate_ok(tmp_path: Path, name: str = "ok.json") -> Path:
    out = tmp_path / name
    rc = main(["simulate", "monkey-saddle", "--out", str(out), "--uv", "0.1,0.1", "--points", "21",
               "--spacing", "0.02", "--quiet"])
    assert rc == 0 and out.is_file()
    return out


@pytest.fixture
def touch(tmp_path) -> dict:
    """A valid touch (3 curves x 21 points, with an outward hint), as a JSON object."""
    obj = json.loads(simulate_ok(tmp_path).read_text())
    assert len(obj["curves"]) == 3 and all(len(c) == 21 for c in obj["curves"])
    return obj


def recognize(path):
    return ["recognize", str(path), "--models", "monkey-saddle", "--quiet"]


def test_the_valid_touch_is_recognised(tmp_path, capsys):
    """The touch all data cases start from is good: only the corruption makes them fail."""
    path = simulate_ok(tmp_path)
    assert main(recognize(path)) == 0
    assert capsys.readouterr().err == ""


# ---------------------------------------------------------------------- 1. data files


def test_data_missing_file(tmp_path, capsys):
    path = tmp_path / "absent.json"
    bad(capsys, recognize(path), path, "no such file")


def test_data_empty_file(tmp_path, capsys):
    path = tmp_path / "empty.json"
    path.write_text("")
    bad(capsys, recognize(path), path, "empty")


def test_data_invalid_json(tmp_path, capsys):
    path = tmp_path / "broken.json"
    path.write_text('{"curves": [[[0, 0, 0], [1, 2, 3]]')
    bad(capsys, recognize(path), path, "not valid JSON")


def test_data_not_utf8(tmp_path, capsys):
    path = tmp_path / "binary.json"
    path.write_bytes(b"\xff\xfe\x00\x81 not text \x80")
    bad(capsys, recognize(path), path, "cannot read")


def _drop_curves(t):
    del t["curves"]


def _two_curves(t):
    t["curves"] = t["curves"][:2]


def _three_points(t):
    t["curves"][0] = t["curves"][0][:3]


def _nan_point(t):
    t["curves"][1][4][2] = float("nan")  # json.dumps writes the literal NaN


def _string_point(t):
    t["curves"][1][4][0] = "abc"


def _two_coordinates(t):
    t["curves"][2][7] = t["curves"][2][7][:2]


def _all_points_two_coordinates(t):
    t["curves"][2] = [p[:2] for p in t["curves"][2]]


def _unknown_units(t):
    t["units"] = "furlong"


def _curves_apart(t):
    t["curves"][2] = [[x + 50.0, y, z] for x, y, z in t["curves"][2]]


def _contact_far(t):
    t["contact"] = [100.0, 100.0, 100.0]


def _zero_outward(t):
    t["outward"] = [0.0, 0.0, 0.0]


def _outward_two_numbers(t):
    t["outward"] = [0.0, 1.0]


def _one_place(t):
    t["curves"][1] = [list(t["curves"][1][0]) for _ in t["curves"][1]]


def _curves_not_a_list(t):
    t["curves"] = "three curves"


@pytest.mark.parametrize("corrupt, problem", [
    (_drop_curves, "missing 'curves'"),
    (_two_curves, "at least 3 curves"),
    (_three_points, "curve 1 has 3 points"),
    (_nan_point, "NaN"),
    (_string_point, "curve 2"),
    (_two_coordinates, "curve 3"),
    (_all_points_two_coordinates, "curve 3"),
    (_unknown_units, "furlong"),
    (_curves_apart, "do not meet"),
    (_contact_far, "do not meet"),
    (_zero_outward, "outward"),
    (_outward_two_numbers, "outward"),
    (_one_place, "one place"),
    (_curves_not_a_list, "'curves' must be a list"),
], ids=lambda x: x.__name__.strip("_") if callable(x) else None)
def test_data_bad_json_content(tmp_path, capsys, touch, corrupt, problem):
    corrupt(touch)
    path = tmp_path / "bad.json"
    text = json.dumps(touch)
    if corrupt is _nan_point:
        assert "NaN" in text
    path.write_text(text)
    bad(capsys, recognize(path), path, problem)


def test_data_json_is_a_list(tmp_path, capsys, touch):
    path = tmp_path / "list.json"
    path.write_text(json.dumps(touch["curves"]))
    bad(capsys, recognize(path), path, "expected a JSON object")


def test_data_unsupported_suffix(tmp_path, capsys, touch):
    path = tmp_path / "touch.txt"
    path.write_text(json.dumps(touch))
    bad(capsys, recognize(path), path, "unsupported data format '.txt'")


def _csv(touch, header="curve,x,y,z"):
    lines = [header]
    for i, c in enumerate(touch["curves"], start=1):
        lines += [f"{i},{x!r},{y!r},{z!r}" for x, y, z in c]
    return lines


def test_data_csv_is_good_before_corruption(tmp_path, capsys, touch):
    path = tmp_path / "ok.csv"
    path.write_text("\n".join(_csv(touch)) + "\n")
    assert main(recognize(path)) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("header", ["curve,stroke,x,y,z", "curve,x,y", "id,x,y,z", "curve,x,y,z,w", "curve,x,x,y,z"])
def test_data_csv_wrong_header(tmp_path, capsys, touch, header):
    path = tmp_path / "bad.csv"
    lines = _csv(touch, header)
    path.write_text("\n".join(lines) + "\n")
    bad(capsys, recognize(path), path, "header")


@pytest.mark.parametrize("value", ["abc", "", "1,5"])
def test_data_csv_non_numeric_coordinate(tmp_path, capsys, touch, value):
    path = tmp_path / "bad.csv"
    lines = _csv(touch)
    curve, x, y, z = lines[10].split(",")
    lines[10] = ",".join([curve, x, f'"{value}"', z])
    path.write_text("\n".join(lines) + "\n")
    bad(capsys, recognize(path), path, "line 11")


def test_data_csv_wrong_field_count(tmp_path, capsys, touch):
    path = tmp_path / "bad.csv"
    lines = _csv(touch)
    lines[5] += ",7"
    path.write_text("\n".join(lines) + "\n")
    bad(capsys, recognize(path), path, "line 6")


def test_data_csv_all_points_identical(tmp_path, capsys, touch):
    touch["curves"][0] = [touch["curves"][0][3]] * len(touch["curves"][0])
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(_csv(touch)) + "\n")
    bad(capsys, recognize(path), path, "curve 1 has all its points at one place")


def test_data_first_bad_file_of_several_is_named(tmp_path, capsys, touch):
    good = simulate_ok(tmp_path, "good.json")
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    line = bad(capsys, ["recognize", good, broken, "--models", "monkey-saddle", "--quiet"], broken, "JSON")
    assert str(good) not in line


# ---------------------------------------------------------------------- 2. model files

GOOD_MODEL = """\
name = "saddle"
[parametric]
x = "u"
y = "v"
z = "u*v"
u = [-1, 1]
v = [-1, 1]
[implicit]
f = "x*y - z"
[table]
resolution = [8, 8]
"""


def _model_commands(model, tmp_path, data=None):
    return {
        "simulate": ["simulate", model, "--out", tmp_path / "out.json", "--points", "21", "--spacing", "0.02",
                     "--quiet"],
        "build": ["build", model, "--out", tmp_path / "db", "--quiet"],
        "recognize": ["recognize", data, "--models", model, "--quiet"],
    }


@pytest.fixture(params=["simulate", "build", "recognize"])
def model_command(request, tmp_path):
    """A function taking a model spec and returning an argv that loads it."""
    data = simulate_ok(tmp_path, "data.json") if request.param == "recognize" else None
    return lambda model: _model_commands(model, tmp_path, data)[request.param]


def test_the_good_model_works(tmp_path, capsys, model_command):
    path = tmp_path / "saddle.toml"
    path.write_text(GOOD_MODEL)
    assert main([str(a) for a in model_command(path)]) == 0
    assert capsys.readouterr().err == ""


def test_model_missing_file(tmp_path, capsys, model_command):
    path = tmp_path / "absent.toml"
    bad(capsys, model_command(path), path, "no such file")


def test_model_unknown_builtin(tmp_path, capsys, model_command):
    bad(capsys, model_command("no-such-model"), "no-such-model", "no such file or built-in model")


def test_model_unknown_format(tmp_path, capsys, model_command):
    path = tmp_path / "saddle.xyz"
    path.write_text(GOOD_MODEL)
    bad(capsys, model_command(path), path, "unsupported model format '.xyz'")


@pytest.mark.parametrize("text, problem", [
    ("", "empty file"),
    ("   \n\n", "empty file"),
    ('name = "saddle"\n[parametric\nx = "u"\n', "not valid TOML"),
    ('name = \n', "not valid TOML"),
    (GOOD_MODEL.replace('z = "u*v"', 'z = "u*foo(v)"'), "unknown function 'foo'"),
    (GOOD_MODEL.replace('f = "x*y - z"', 'f = "x*y - z + 1"'), "implicit f is not zero"),
    (GOOD_MODEL.replace('f = "x*y - z"', 'f = "x*y + z"'), "implicit f is not zero"),
    (GOOD_MODEL.replace("u = [-1, 1]", "u = [1, 0]"), "not an interval"),
    (GOOD_MODEL.replace("v = [-1, 1]", "v = [0, 0]"), "not an interval"),
    (GOOD_MODEL.replace('z = "u*v"\n', ""), "needs 'z'"),
    (GOOD_MODEL.replace('z = "u*v"', 'z = "u*v*w"'), "unknown name 'w'"),
    (GOOD_MODEL.replace('z = "u*v"', 'z = "u*(v"'), "cannot parse"),
    (GOOD_MODEL.replace('name = "saddle"', 'name = "saddle"\ncolour = "red"'), "unknown key"),
], ids=["empty", "blank", "toml-table", "toml-value", "unknown-function", "implicit-shifted",
        "implicit-wrong", "domain-reversed", "domain-empty", "missing-z", "unknown-name", "unbalanced",
        "unknown-key"])
def test_model_bad_file(tmp_path, capsys, model_command, text, problem):
    path = tmp_path / "saddle.toml"
    path.write_text(text)
    bad(capsys, model_command(path), path, problem)


@pytest.mark.parametrize("key, expression", [
    ("z", "__import__('os').system('echo hi')"),
    ("z", "u.real*v"),
    ("f", "x.real*y - z"),
    ("f", "x*y - z + (lambda: 0)()"),
    ("z", "u*v if u else 0"),
    ("z", "[u for u in ()]"),
    ("z", "().__class__.__bases__[0]"),
    ("f", "sin.__self__"),
], ids=["import", "attribute-z", "attribute-f", "lambda", "conditional", "comprehension", "dunder",
        "function-attribute"])
def test_model_python_in_expression_is_not_allowed(tmp_path, capfd, key, expression):
    """Nothing from a model file is run as Python: such expressions are refused, by name."""
    old = {"z": 'z = "u*v"', "f": 'f = "x*y - z"'}[key]
    path = tmp_path / "evil.toml"
    path.write_text(GOOD_MODEL.replace(old, f"{key} = {json.dumps(expression)}"))
    out = tmp_path / "out.json"
    bad(capfd, ["simulate", path, "--out", out, "--quiet"], path, "not allowed")
    assert not out.exists()


# ---------------------------------------------------------------------- 3. databases


@pytest.fixture
def db(tmp_path) -> Path:
    path = tmp_path / "db"
    assert main(["build", "monkey-saddle", "--out", str(path), "--quiet"]) == 0
    return path


@pytest.fixture
def data(tmp_path) -> Path:
    return simulate_ok(tmp_path, "data.json")


def test_the_database_works(db, data, capsys):
    assert main(["recognize", str(data), "--db", str(db), "--quiet"]) == 0
    assert capsys.readouterr().err == ""


def _npz(db: Path) -> Path:
    (npz,) = db.glob("*.npz")
    return npz


def test_db_missing_folder(tmp_path, data, capsys):
    path = tmp_path / "no-db"
    bad(capsys, ["recognize", data, "--db", path], path, "no such database")


def test_db_is_a_file(tmp_path, data, capsys):
    bad(capsys, ["recognize", data, "--db", data], data, "folder")


def test_db_without_index(tmp_path, data, capsys):
    path = tmp_path / "empty-db"
    path.mkdir()
    bad(capsys, ["recognize", data, "--db", path], path, "no index.json")


@pytest.mark.parametrize("text", ["{not json", "", '{"format": "something-else", "models": []}', "[1, 2]",
                                  '{"format": "tactrec-db", "version": 3, "models": [{"name": "x"}]}'],
                         ids=["not-json", "empty", "other-format", "list", "incomplete-entry"])
def test_db_index_broken(db, data, capsys, text):
    index = db / "index.json"
    index.write_text(text)
    bad(capsys, ["recognize", data, "--db", db], index, "corrupted database index")


def test_db_of_an_older_format_asks_for_a_rebuild(db, data, capsys):
    import json

    index = db / "index.json"
    old = json.loads(index.read_text())
    old["version"] = 1
    index.write_text(json.dumps(old))
    bad(capsys, ["recognize", data, "--db", db], index, "format version 1, this tactrec reads version 3: rebuild it")


def test_db_npz_altered(db, data, capsys):
    npz = _npz(db)
    blob = bytearray(npz.read_bytes())
    for i in range(len(blob) // 2, len(blob) // 2 + 16):
        blob[i] ^= 0xFF
    npz.write_bytes(bytes(blob))
    bad(capsys, ["recognize", data, "--db", db], npz, "checksum")


def test_db_npz_truncated(db, data, capsys):
    npz = _npz(db)
    npz.write_bytes(npz.read_bytes()[:100])
    bad(capsys, ["recognize", data, "--db", db], npz, "corrupted database file")


def test_db_npz_deleted(db, data, capsys):
    npz = _npz(db)
    npz.unlink()
    bad(capsys, ["recognize", data, "--db", db], npz, "missing from the database")


# ---------------------------------------------------------------------- 4. arguments


def _simulate(tmp_path, *extra):
    return ["simulate", "monkey-saddle", "--out", tmp_path / "out.json", "--quiet", *extra]


@pytest.mark.parametrize("extra, name, problem", [
    (["--points", "2"], "--points", "at least 5"),
    (["--points", "many"], "--points", "not a whole number"),
    (["--spacing", "-1"], "--spacing", "positive"),
    (["--spacing", "0"], "--spacing", "positive"),
    (["--spacing", "nan"], "--spacing", "positive"),
    (["--noise", "-0.1"], "--noise", "non-negative"),
    (["--curves", "2"], "--curves", "at least 3"),
    (["--uv", "1,2,3"], "--uv", "expected 2"),
    (["--uv", "a,b"], "--uv", "expected 2"),
    (["--uv", "0.1,inf"], "--uv", "finite"),
    (["--at", "1,2"], "--at", "expected 3"),
    (["--uv", "0.1,0.1", "--at", "0,0,0"], "--at", "at most one"),
    (["--noise-kind", "pink"], "--noise-kind", "invalid choice"),
], ids=["points-2", "points-word", "spacing-negative", "spacing-zero", "spacing-nan", "noise-negative",
        "curves-2", "uv-three", "uv-words", "uv-inf", "at-two", "uv-and-at", "noise-kind"])
def test_simulate_bad_argument(tmp_path, capsys, extra, name, problem):
    bad(capsys, _simulate(tmp_path, *extra), name, problem)
    assert files_in(tmp_path) == []


def test_bad_argument_is_not_blamed_on_the_model(tmp_path, capsys):
    """``--uv 1,2,3`` is wrong, not the model: the line names the argument first."""
    line = bad(capsys, _simulate(tmp_path, "--uv", "1,2,3"), "--uv", "expected 2")
    assert line.startswith("tactrec: --uv: "), line


def test_recognize_needs_db_or_models(tmp_path, data, capsys):
    bad(capsys, ["recognize", data], "--db", "give either --db DB or --models")


def test_recognize_not_both_db_and_models(db, data, capsys):
    bad(capsys, ["recognize", data, "--db", db, "--models", "monkey-saddle"], "--db", "give either")


def test_recognize_bad_delta(data, capsys):
    bad(capsys, ["recognize", data, "--models", "monkey-saddle", "--delta", "-2"], "--delta", "positive")


def test_bench_unknown_benchmark(tmp_path, capsys):
    bad(capsys, ["bench", "no-such-benchmark", "--out", tmp_path / "bench"], "no-such-benchmark",
        "unknown benchmark")
    assert files_in(tmp_path) == []


def test_bench_sweep_options_belong_to_their_benchmarks(tmp_path, capsys):
    bad(capsys, ["bench", "kernels", "--scans", "paper-like", "--out", tmp_path / "bench"], "kernels",
        "--scans applies to paper-fig11, paper-table6, paper-steps, fast-vs-paper, fit-limit, field only")
    bad(capsys, ["bench", "paper-fig11", "--scans", "other", "--out", tmp_path / "bench"], "paper-fig11",
        "paper-fig11 takes --scans shipped or paper-like, not other")
    bad(capsys, ["bench", "fit-limit", "--scans", "paper-like", "--out", tmp_path / "bench"], "fit-limit",
        "fit-limit takes --scans shipped, other or cad, not paper-like")
    bad(capsys, ["bench", "kernels", "--delta-only", "--out", tmp_path / "bench"], "kernels",
        "--delta-only applies to paper-fig11 only")
    bad(capsys, ["bench", "paper-table6", "--lengths", "9,24", "--out", tmp_path / "bench"], "paper-table6",
        "--lengths applies to paper-fig11 only")
    bad(capsys, ["bench", "paper-fig11", "--delta-only", "--angles", "10", "--out", tmp_path / "bench"],
        "paper-fig11", "--delta-only leaves l and phi at the defaults")
    bad(capsys, ["bench", "paper-fig11", "--lengths", "9,-1", "--out", tmp_path / "bench"], "--lengths",
        "positive")
    bad(capsys, ["bench", "kernels", "--sets", "hard", "--out", tmp_path / "bench"], "kernels",
        "--sets applies to calibration, multi-touch, open-world, sensor, patch, contacts and contact-search only")
    bad(capsys, ["bench", "kernels", "--radii", "6", "--out", tmp_path / "bench"], "kernels",
        "--radii applies to patch only")
    bad(capsys, ["bench", "patch", "--blur", "-1", "--out", tmp_path / "bench"], "patch", "--blur must be")
    bad(capsys, ["calibrate", "--db", tmp_path / "db", "--kinds", "curves,gel"], "--kinds", "kinds among")
    bad(capsys, ["bench", "multi-touch", "--sets", "hard-10,soft", "--out", tmp_path / "bench"], "--sets",
        "unknown set 'soft'")
    bad(capsys, ["bench", "calibration", "--strategies", "next", "--out", tmp_path / "bench"], "calibration",
        "--strategies applies to multi-touch and contacts only")
    bad(capsys, ["bench", "multi-touch", "--strategies", "next,greedy", "--out", tmp_path / "bench"],
        "--strategies", "unknown strategy 'greedy'")
    bad(capsys, ["bench", "patch", "--first-instance", "1", "--out", tmp_path / "bench"], "patch",
        "--first-instance applies to contacts only")
    bad(capsys, ["bench", "contacts", "--instances", "3", "--first-instance", "3", "--out", tmp_path / "bench"],
        "contacts", "leaves no instance below --instances 3")
    assert files_in(tmp_path) == []


@pytest.mark.parametrize("argv, name, problem", [
    ([], "command", "required"),
    (["simulate", "monkey-saddle"], "--out", "required"),
    (["simulate"], "MODEL", "required"),
    (["build", "monkey-saddle"], "--out", "required"),
    (["build", "--out", "db"], "MODEL", "required"),
    (["recognize", "--models", "monkey-saddle"], "DATA", "required"),
    (["bench"], "NAME", "required"),
    (["no-such-command"], "no-such-command", "invalid choice"),
    (["simulate", "monkey-saddle", "--out", "x.json", "--colour", "red"], "--colour", "unrecognized"),
], ids=["command", "simulate-out", "simulate-model", "build-out", "build-model", "recognize-data", "bench-name",
        "unknown-command", "unknown-option"])
def test_missing_or_unknown_argument(tmp_path, capsys, monkeypatch, argv, name, problem):
    monkeypatch.chdir(tmp_path)
    bad(capsys, argv, name, problem)
    assert files_in(tmp_path) == []


# ---------------------------------------------------------------------- 5. no half-written output


def test_simulate_broken_model_writes_nothing(tmp_path, capsys):
    model = tmp_path / "broken.toml"
    model.write_text(GOOD_MODEL.replace('f = "x*y - z"', 'f = "x*y - z + 1"'))
    out = tmp_path / "out" / "touch.json"
    bad(capsys, ["simulate", model, "--out", out, "--quiet"], model, "not zero")
    assert not out.parent.exists()
    assert files_in(tmp_path) == ["broken.toml"]


@pytest.mark.parametrize("suffix", [".json", ".csv"])
def test_simulate_leaving_the_surface_writes_nothing(tmp_path, capsys, suffix):
    out = tmp_path / f"touch{suffix}"
    bad(capsys, ["simulate", "monkey-saddle", "--out", out, "--uv", "0.99,0.99", "--spacing", "0.05",
                 "--points", "61", "--quiet"], "monkey-saddle", "leaves the surface")
    assert files_in(tmp_path) == []


def test_simulate_failure_keeps_an_existing_output(tmp_path, capsys):
    out = tmp_path / "touch.json"
    out.write_text("old contents\n")
    bad(capsys, ["simulate", "monkey-saddle", "--out", out, "--uv", "0.99,0.99", "--spacing", "0.05",
                 "--points", "61", "--quiet"], "monkey-saddle", "leaves the surface")
    assert out.read_text() == "old contents\n"
    assert files_in(tmp_path) == ["touch.json"]


def test_build_with_a_broken_model_writes_nothing(tmp_path, capsys):
    """A good model before a broken one must not leave a database without an index."""
    model = tmp_path / "broken.toml"
    model.write_text(GOOD_MODEL.replace("u = [-1, 1]", "u = [1, 0]"))
    out = tmp_path / "db"
    bad(capsys, ["build", "monkey-saddle", model, "--out", out, "--quiet"], model, "not an interval")
    assert files_in(out) == []


def test_build_with_two_models_of_one_name_writes_nothing(tmp_path, capsys):
    copy = tmp_path / "copy.toml"
    copy.write_text(GOOD_MODEL.replace('name = "saddle"', 'name = "monkey-saddle"'))
    out = tmp_path / "db"
    bad(capsys, ["build", "monkey-saddle", copy, "--out", out, "--quiet"], copy, "two models are named")
    assert files_in(out) == []


def test_failed_rebuild_keeps_the_database(db, data, tmp_path, capsys):
    before = {p.name: p.read_bytes() for p in db.iterdir()}
    good = tmp_path / "saddle.toml"
    good.write_text(GOOD_MODEL)
    model = tmp_path / "broken.toml"
    model.write_text("")
    bad(capsys, ["build", good, model, "--out", db, "--quiet"], model, "empty file")
    assert {p.name: p.read_bytes() for p in db.iterdir()} == before
    assert main(["recognize", str(data), "--db", str(db), "--quiet"]) == 0


def test_bench_paper_option_is_checked_before_any_work(tmp_path, capsys):
    bad(capsys, ["bench", "paper-fig11", "--paper-option", "parabola_points=1", "--out", tmp_path / "bench"],
        "--method", "parabola_points must be a whole number >= 2")
    bad(capsys, ["bench", "paper-fig11", "--paper-option", "no_such=3", "--out", tmp_path / "bench"],
        "--method", "has no option 'no_such'")
    bad(capsys, ["bench", "paper-fig11", "--paper-option", "phi_step", "--out", tmp_path / "bench"],
        "--paper-option", "expected NAME=VALUE")
    bad(capsys, ["bench", "kernels", "--paper-option", "phi_step=5", "--out", tmp_path / "bench"], "kernels",
        "--paper-option applies to paper-example, paper-table2, paper-table3, paper-table6, paper-fig11 only")
    bad(capsys, ["bench", "paper-table3", "--method", "fast", "--paper-option", "parabola_points=3",
                 "--out", tmp_path / "bench"], "fast", "--paper-option applies to the paper method only")
    for name in ("paper-example", "paper-table2", "paper-table6"):
        bad(capsys, ["bench", name, "--paper-option", "parabola_points=1", "--out", tmp_path / "bench"],
            "--method", "parabola_points must be a whole number >= 2")
    assert files_in(tmp_path) == []


# ------------------------------------------------------- absurd coordinates


def test_absurd_coordinates_are_refused_before_arithmetic(tmp_path, capsys):
    """Coordinates no sensor records (beyond 1e12, a touch spanning under 1e-12, or one a million
    times its extent from its frame's origin) and touches a thousand times off every model's size are refused in one line
    naming the file, before any arithmetic could warn."""
    obj = json.loads(simulate_ok(tmp_path).read_text())

    def written(name, move):
        out = dict(obj, curves=[[move(p) for p in c] for c in obj["curves"]])
        out.pop("outward", None)
        path = tmp_path / name
        path.write_text(json.dumps(out))
        return path

    bad(capsys, recognize(written("huge.json", lambda p: [x * 1e200 for x in p])), "huge.json", "beyond 1e+12")
    bad(capsys, recognize(written("far.json", lambda p: [x + 1e9 for x in p])), "far.json", "from its frame's origin")
    bad(capsys, recognize(written("speck.json", lambda p: [x * 1e-20 for x in p])), "speck.json", "under 1e-12")
    bad(capsys, recognize(written("large.json", lambda p: [x * 1e7 for x in p])), "large.json", "are its units right")
    bad(capsys, recognize(written("small.json", lambda p: [x * 1e-7 for x in p])), "small.json", "are its units right")


def test_fuzzed_magnitudes_give_a_result_or_one_line(tmp_path, capfd):
    """200 seeded touch files whose coordinates are scaled and shifted by powers of ten from 1e-300 to
    1e300, some with one coordinate blown up: each gives a result (exit 0) or one ``tactrec:`` line
    (exit 2), and nothing else reaches stderr (no numpy warning, no LAPACK message)."""
    import numpy as np

    obj = json.loads(simulate_ok(tmp_path).read_text())
    obj.pop("outward", None)
    rng = np.random.default_rng(50)
    outcomes = {0: 0, 2: 0}
    for k in range(200):
        scale = 10.0 ** rng.uniform(-300, 300) if k % 4 else 10.0 ** rng.uniform(-4, 4)
        shift = rng.choice((-1.0, 1.0)) * 10.0 ** rng.uniform(-300, 300) if k % 3 else 0.0
        curves = np.array(obj["curves"]) * scale + shift
        if k % 5 == 0:
            curves[rng.integers(3), rng.integers(21), rng.integers(3)] = rng.choice((-1.0, 1.0)) * 10.0 ** rng.uniform(
                -300, 300)
        path = tmp_path / f"fuzz{k}.json"
        path.write_text(json.dumps(dict(obj, curves=curves.tolist())))
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)           # a numpy warning fails the run
            rc = main(recognize(path))
        captured = capfd.readouterr()
        lines = captured.err.strip().splitlines()
        assert rc in outcomes, (k, captured.err)
        assert (rc == 0 and not lines) or (rc == 2 and len(lines) == 1 and lines[0].startswith("tactrec: ")), \
            (k, captured.err)
        outcomes[rc] += 1
    assert outcomes[0] >= 5 and outcomes[2] >= 100


@pytest.mark.parametrize("field, value", [
    ("contact", [1e300, 0.0, 0.0]), ("outward", [1e300, 1.0, 0.0]), ("tip_radius", 10 ** 400),
    ("curves", "integers"), ("contact", [10 ** 400, 0, 0]),
])
def test_absurd_fields_are_one_line(tmp_path, capfd, field, value):
    """A contact, outward hint or tip radius beyond any sensor's reach, and whole numbers too large for
    a float, are one line naming the file (no warning, no traceback)."""
    obj = json.loads(simulate_ok(tmp_path).read_text())
    if value == "integers":
        obj["curves"][1][3] = [10 ** 400, 0, 0]
    else:
        obj[field] = value
    path = tmp_path / "absurd.json"
    path.write_text(json.dumps(obj))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        rc = main(recognize(path))
    lines = capfd.readouterr().err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "absurd.json" in lines[0], lines


@pytest.mark.parametrize("change", ["translation", "rotation", "missed start", "missed length"])
def test_absurd_session_poses_and_lines_are_one_line(tmp_path, capfd, change):
    """A session whose sensor2world puts a touch beyond any sensor's reach, whose rotation is no
    rotation, or whose missed line starts or runs absurdly far, is one line naming the file."""
    obj = json.loads(simulate_ok(tmp_path).read_text())
    pose = {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0, 0, 0]}
    missed = {"start": [0, 0, 0], "direction": [0, 0, 1], "length": 1.0}
    if change == "translation":
        pose["translation"] = [1e200, 0, 0]
    elif change == "rotation":
        pose["rotation"] = [[1e300, 0, 0], [0, 1, 0], [0, 0, 1]]
    elif change == "missed start":
        missed["start"] = [1e300, 0, 0]
    else:
        missed["length"] = 10 ** 400
    touches = [dict(obj, sensor2world=pose), {"missed": missed}]
    path = tmp_path / "session.json"
    path.write_text(json.dumps({"touches": touches}))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        rc = main(["recognize", str(path), "--models", "monkey-saddle", "--quiet"])
    lines = capfd.readouterr().err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "session.json" in lines[0], lines
