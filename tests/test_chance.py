"""The null model of chance fits (tactrec.chance): fitted on a database's own models, stored with it,
and what it does to the probabilities of touches of models in the database and of models left out."""

import dataclasses
import json
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from tactrec.chance import FILE, PENALTIES, catalogue_key, load, save
from tactrec.chance.fit import calibrate
from tactrec.cli import main
from tactrec.database import build_database, build_entries, load_database
from tactrec.errors import InputError
from tactrec.recognition import Recognizer
from tactrec.simulation import simulate_random_touch

MODELS = ["sphere-33", "cylinder-50", "ellipsoid", "cylinder-94"]
LENGTHS = (6.0, 16.0)


@pytest.fixture(scope="module")
def fitted():
    db = build_entries(MODELS)
    with Recognizer(db.entries) as r:
        model = calibrate(r, touches=6, seed=0, lengths=LENGTHS)
    return db, model


def _touches(db, count, seed, model=None):
    """``count`` seeded touches, alternately noisy and clean, each of a model in turn: (index, data);
    ``model``: only those of that model (index)."""
    out = []
    for i in range(count):
        rng = np.random.default_rng([seed, i])
        m = i % len(db.entries)
        if model is not None and m != model:
            continue
        noisy = i % 2 == 0
        data = simulate_random_touch(db.entries[m].model, rng=rng, points=41, spacing=(8.0 if noisy else 14.0) / 40,
                                     angle=30.0 if noisy else 60.0, noise=0.03 if noisy else 0.0,
                                     noise_kind="gaussian", outward=not noisy)
        out.append((m, data))
    return out


def test_left_out_models_come_back_unknown_and_known_ones_right(fitted):
    """20 seeded touches not used in the fit, half noisy, half clean.  With the null model, a touch of a
    model left out of the search comes back unknown (its most probable outcome) in at least 16 and
    is never sure (>= 0.95) of a model; a touch of a model in it names that model as the most
    probable model in at least 18, and each clean one beats unknown in at least 9 of 10 (a noisy
    patch of the sphere fits the cylinders too, and then known and left out look alike)."""
    db, model = fitted
    names = [e.name for e in db.entries]
    left_unknown = known_best = clean_right = 0
    with Recognizer(db.entries, chance=model) as r:
        for i, (m, data) in enumerate(_touches(db, 20, seed=1234)):
            whole = r.recognize(data)
            known_best += whole.best == names[m]
            clean_right += i % 2 == 1 and whole.best == names[m] and whole.confidence > whole.unknown
            left = r.recognize(data, among=names[:m] + names[m + 1:])
            # scored as a database without the model would be: by a null model that never saw it
            p, unknown = left.evidence.outcomes(chance=model.without([names[m]]))
            left_unknown += unknown > p.max()
            assert p.max() < 0.95, (names[m], left.best, p.max())
    assert left_unknown >= 16
    assert known_best >= 18
    assert clean_right >= 9


def test_stored_with_the_database_and_read_back(tmp_path, fitted):
    db, model = fitted
    build_database(MODELS, tmp_path / "db", quiet=True)
    save(model, tmp_path / "db")
    loaded = load_database(tmp_path / "db")
    assert loaded.chance is not None
    assert loaded.chance.key == catalogue_key(loaded.entries) == model.key
    assert np.allclose(loaded.chance.known, model.known, atol=1e-6)
    # the prior chosen when it was fitted is read back, not chosen again on the rounded statistics
    assert loaded.chance.fitted_penalty == model.penalty
    assert all(np.isclose(loaded.chance.ratio(x, x + 0.5, r), model.ratio(x, x + 0.5, r), rtol=1e-4)
               for x in (-1.0, 0.0, 1.0) for r in model.resolving[::7])
    other = next(p for p in PENALTIES if p != model.penalty)
    save(dataclasses.replace(model, fitted_penalty=other), tmp_path / "db")
    assert load(tmp_path / "db").penalty == other
    # a model left out chooses its own, once
    left = model.without([MODELS[0]])
    assert left.fitted_penalty is None and left is model.without([MODELS[0]]) and left.penalty in PENALTIES
    with Recognizer(loaded) as r:                       # a database's recognizer takes its null model
        assert r.chance is loaded.chance


def test_each_kind_of_touch_is_weighed_against_its_own_calibration_touches(tmp_path, fitted):
    """Calibration touches of another kind whose known and left-out fits look alike (chance fits
    everywhere) leave the curves' ratios as they were and give touches of their kind no evidence
    either way; a kind with too few calibration touches (here patches, before they are added) is
    weighed against all of them; the kinds are stored with the statistics and kept by ``without``."""
    _, model = fitted
    n = len(model)
    alike = np.column_stack([np.linspace(-1.5, 1.5, n), np.linspace(-1.0, 2.0, n)])
    mixed = dataclasses.replace(model, resolving=np.concatenate([model.resolving, model.resolving]),
                                known=np.vstack([model.known, alike]), unknown=np.vstack([model.unknown, alike]),
                                touched=model.touched * 2, kinds=("curves",) * n + ("patch",) * n,
                                fitted_penalty=model.penalty)
    for r in model.resolving[::5]:
        for x1, lead in ((-1.0, 1.5), (0.0, 0.5), (1.0, 0.0)):
            x2 = min(x1 + lead, 2.0)
            assert mixed.ratio(x1, x2, r) == pytest.approx(model.ratio(x1, x2, r), rel=1e-12)
            assert model.ratio(x1, x2, r, kind="patch") == model.ratio(x1, x2, r)      # too few patches: all
            assert 0.5 < mixed.ratio(x1, x2, r, kind="patch") < 2.0
    save(mixed, tmp_path)
    back = load(tmp_path)
    assert back.kind_of == mixed.kind_of and back.pool("patch").tolist() == list(range(n, 2 * n))
    left = back.without([MODELS[0]])
    assert MODELS[0] not in left.touched and len(left.kind_of) == len(left)
    assert [k for k, t in zip(left.kind_of, left.touched) if t == MODELS[1]] == \
        [k for k, t in zip(mixed.kind_of, mixed.touched) if t == MODELS[1]]


def test_a_null_model_of_other_models_is_not_used(tmp_path, fitted):
    db, model = fitted
    build_database(MODELS[:3], tmp_path / "db", quiet=True)
    save(model, tmp_path / "db")
    lines = []
    loaded = load_database(tmp_path / "db", warn=lines.append)
    assert loaded.chance is None
    assert len(lines) == 1 and FILE in lines[0] and "calibrate" in lines[0]


@pytest.mark.parametrize("text", ["{not json", json.dumps({"format": "tactrec-chance", "version": 1}),
                                  json.dumps({"format": "other"}), '{"format": "tactrec-chance", "version": 1, '
                                  '"key": "k", "method": "fast", "seed": 1e400, "touches": 2, "resolving": [], '
                                  '"known": [], "unknown": [], "touched": []}', '{"format": "tactrec-chance", '
                                  '"version": 1, "key": "k", "method": "fast", "seed": 0, "touches": 2, "resolving": '
                                  '[1.0], "known": [[0, 1]], "unknown": [[1, 1]], "touched": ["a"], "penalty": "0.1"}',
                                  '{"format": "tactrec-chance", "version": 1, "key": "k", "method": "fast", "seed": 0, '
                                  '"touches": 2, "resolving": [1.0], "known": [[0, 1]], "unknown": [[1, 1]], '
                                  '"touched": ["a"], "kinds": ["gel"]}'])
def test_a_damaged_null_model_is_named_set_aside_and_calibrated_again(tmp_path, capsys, text):
    """Read directly, a damaged null model is an error naming its file; a database holding one says so
    in one warning line and scores by the fit test alone; ``tactrec calibrate`` writes it again."""
    db = tmp_path / "db"
    assert main(["build", "sphere-33", "cylinder-50", "--out", str(db), "--quiet"]) == 0
    (db / FILE).write_text(text)
    with pytest.raises(InputError, match=FILE):
        load(db)
    data = tmp_path / "t.json"
    assert main(["simulate", "sphere-33", "--out", str(data), "--seed", "1", "--spacing", "0.2"]) == 0
    capsys.readouterr()
    assert main(["recognize", str(data), "--db", str(db), "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["calibrated"] is False
    assert len(err.strip().splitlines()) == 1 and FILE in err and "calibrate" in err
    assert main(["calibrate", "--db", str(db), "--touches", "2", "--lengths", "6,16", "--kinds", "curves",
                 "--quiet"]) == 0
    assert load(db) is not None


def test_a_null_model_of_other_models_or_another_method_is_refused(fitted):
    db, model = fitted
    with pytest.raises(InputError, match="other models"):
        Recognizer(db.entries[:3], chance=model)
    with pytest.raises(InputError, match="fast"):
        Recognizer(db.entries, method="paper", chance=model)
    assert Recognizer(db.entries, chance=False).chance is None


def test_the_ratio_never_reads_a_worse_fit_or_a_smaller_lead_as_more_evidence(fitted):
    """Over a grid of best fits and leads at the calibration's resolving powers, the ratio of known
    against unknown never rises as the best fit worsens or falls as its lead over the second grows,
    and claims no more than its calibration touches can show: no ratio beyond ``touches + 1`` either
    way, and a touch more resolving than every calibration touch read as the most resolving one."""
    _, model = fitted
    for r in np.unique(np.round(model.resolving, 1)):
        for lead in (0.0, 0.1, 0.5, 1.0, 3.0):
            along = [model.ratio(x1, min(x1 + lead, 2.0), r) for x1 in np.linspace(-2.0, 2.0, 17)]
            assert all(b <= a * (1 + 1e-9) for a, b in zip(along, along[1:])), (r, lead, along)
        for x1 in (-2.0, -0.5, 0.0, 0.3, 1.0):
            across = [model.ratio(x1, min(x1 + lead, 2.0), r) for lead in np.linspace(0.0, 4.0, 17)]
            assert all(b >= a * (1 - 1e-9) for a, b in zip(across, across[1:])), (r, x1, across)
    n, top = len(model), float(np.max(model.resolving))
    for x, d in ((-2.0, 0.0), (-2.0, 4.0), (0.0, 0.0), (2.0, 0.0), (2.0, 4.0)):
        beyond = model.ratio(x, min(x + d, 2.0), top + 2.0)
        assert 1 / (n + 1) <= beyond <= n + 1
        assert beyond == pytest.approx(model.ratio(x, min(x + d, 2.0), top), rel=1e-9)


def test_calibrate_command_writes_it_and_recognize_reports_it(tmp_path, capsys):
    db = tmp_path / "db"
    assert main(["build", "sphere-33", "cylinder-50", "--out", str(db), "--quiet"]) == 0
    assert main(["calibrate", "--db", str(db), "--touches", "2", "--lengths", "6,16", "--quiet"]) == 0
    assert (db / FILE).is_file() and set(load(db).kind_of) == {"curves", "patch"}      # by default both kinds
    data = tmp_path / "t.json"
    assert main(["simulate", "sphere-33", "--out", str(data), "--seed", "1", "--spacing", "0.2"]) == 0
    capsys.readouterr()
    assert main(["recognize", str(data), "--db", str(db), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["calibrated"] is True
    assert result["best"] == "sphere-33"
    assert abs(sum(r["probability"] for r in result["ranking"] if "probability" in r) + result["unknown"] - 1) < 1e-9


def test_bad_calibration_arguments_are_one_line(tmp_path, capsys):
    db = tmp_path / "db"
    assert main(["build", "sphere-33", "--out", str(db), "--quiet"]) == 0
    assert main(["calibrate", "--db", str(db), "--quiet"]) == 2          # one model: nothing to leave it out among
    assert "at least two models" in capsys.readouterr().err
    assert main(["calibrate", "--db", str(tmp_path / "none"), "--quiet"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_twins_that_differ_nowhere_are_never_sure(tmp_path, fitted):
    """A database holding two copies of one surface under two names: no touch of it, noise-free or
    noisy, tells them apart, so none of 20 seeded touches is sure (>= 0.95) of either, with its
    null model and by the fit test alone."""
    db, _ = fitted
    twin = tmp_path / "twin.toml"
    text = (Path(resources.files("tactrec")) / "surfaces" / "builtin" / "sphere-33.toml").read_text()
    twin.write_text(text.replace('name = "sphere-33"', 'name = "sphere-twin"'))
    twins = build_entries(["sphere-33", str(twin), "cylinder-50"])
    with Recognizer(twins.entries) as r:
        model = calibrate(r, touches=4, seed=0, lengths=LENGTHS)
    sphere = _touches(twins, 60, seed=7, model=0)
    assert len(sphere) == 20
    for chance in (model, None):
        with Recognizer(twins.entries, chance=chance) as r:
            for _, data in sphere:
                found = r.recognize(data)
                assert found.best in ("sphere-33", "sphere-twin")
                assert found.confidence < 0.95, (found.best, found.probabilities)
