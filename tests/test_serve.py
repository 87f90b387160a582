"""``tactrec serve`` (tactrec.service): a real service process driven through a session, fuzzed with
malformed requests, and the same answers as the Python calls it stands for."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from tactrec.database import open_models
from tactrec.recognition import Recognizer
from tactrec.service import Service
from tactrec.simulation import random_rigid_motion, sensor_to_world, simulate_random_touch

MODELS = ["sphere-33", "cylinder-50", "elliptic-cylinder"]
TOUCH = dict(points=21, spacing=1.0, angle=60.0, noise=0.01, noise_kind="gaussian", outward=True)


@pytest.fixture(scope="module")
def db():
    return open_models(db=None, models=MODELS, warn=print, quiet=True, units=None, scale=None)


def _touch(name, db, key):
    model = next(e.model for e in db if e.name == name)
    return simulate_random_touch(model, rng=np.random.default_rng((41, key)), **TOUCH)


def _session_touches(db, count):
    """``count`` touches of the sphere, each in its own sensor frame, with ``sensor2world``."""
    pose = random_rigid_motion(np.random.default_rng((42,)), extent=200.0)
    out = []
    for i in range(count):
        data = _touch("sphere-33", db, i)
        R, t = sensor_to_world(data, pose)
        out.append(dict(data.to_json(), sensor2world={"rotation": R.tolist(), "translation": t.tolist()}))
    return out


def _serve(lines: list[str], timeout: float = 600.0) -> list[dict]:
    """Run a real ``tactrec serve`` on the models over ``lines``: its answers, one per line, in order."""
    proc = subprocess.run([sys.executable, "-m", "tactrec", "serve", "--models", *MODELS, "--quiet"],
                          input="\n".join(lines) + "\n", capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    return [json.loads(line) for line in proc.stdout.splitlines()]


def _malformed(rng, good: dict, count: int) -> list[str]:
    """``count`` request lines, each bad in one seeded way: random bytes, a good request cut short,
    or well-formed JSON that is not a valid request (wrong kinds, fields, types, values)."""
    curves = good["curves"]
    far = [[[x + 1000.0 * k, y, z] for x, y, z in c] for k, c in enumerate(curves)]   # curves that do not meet
    bad_touches = [None, "abc", 3, [], {}, {"curves": []}, {"curves": [[[0, 0, 0]]] * 3},
                   {"curves": curves[:2]}, {"curves": curves, "units": "furlong"},
                   {"curves": curves, "outward": [0, 0, 0]}, {"curves": curves, "tip_radius": -1},
                   {"curves": [[[1e300, 0, 0]] + c[1:] for c in curves]}, {"curves": far},
                   {"curves": [[["x", 0, 0]] + c[1:] for c in curves]}, {"curves": curves, "contact": [1, 2]}]
    shapes = [
        lambda k: {"id": k, "recognize": bad_touches[rng.integers(len(bad_touches))]},
        lambda k: {"id": k, "session": "s", "add": bad_touches[rng.integers(len(bad_touches))]},
        lambda k: {"id": k, "session": f"none-{k}", "next": {"radius": 10}},
        lambda k: {"id": k, "session": f"none-{k}", "close": True},
        lambda k: {"id": k, "session": int(k), "add": good},
        lambda k: {"id": k, "add": good},
        lambda k: {"id": k, "recognize": good, "next": {}},
        lambda k: {"id": [k], "recognize": good},
        lambda k: {"id": k, "session": "s", "add": dict(good, sensor2world={"rotation": np.diag([2.0, 1, 1]).tolist(),
                                                                              "translation": [0, 0, 0]})},
        lambda k: {"id": k, "session": "s", "add": {"missed": {"start": [0, 0, 0], "direction": [0, 0, 1],
                                                               "length": 5}}},
        lambda k: {"id": k, "session": "s", "add": dict(good, sensor2world=[1, 2, 3])},
        lambda k: {"id": k, "recognize": good, "extra": 1},
        lambda k: {"id": k},
    ]
    text = json.dumps({"id": 0, "recognize": good})
    out = []
    for k in range(count):
        kind = rng.integers(8)
        if kind == 0:                                       # random bytes (no line breaks), as text
            raw = rng.integers(1, 256, size=int(rng.integers(1, 120)), dtype=np.uint8).tobytes()
            line = "x" + raw.decode("latin-1").replace("\n", " ").replace("\r", " ")
        elif kind == 1:                                     # a good request cut short
            line = text[:int(rng.integers(1, len(text) - 1))]
        elif kind == 2:
            line = json.dumps(shapes[rng.integers(len(shapes))](k))
        elif kind == 3:                                     # a number no JSON has, and too deep a nesting
            line = text.replace(str(curves[0][0][0]), ["NaN", "Infinity", "-Infinity"][rng.integers(3)], 1)
            line = line if rng.random() < 0.5 else "[" * 100000
        elif kind == 4:                                     # not an object
            line = json.dumps([None, 1, "recognize", [good]][rng.integers(4)])
        elif kind == 5:                                     # a bad 'next' on a session's name, never opened
            line = json.dumps({"id": k, "session": "s", "next": {"radius": [-1, 0, "far", None][rng.integers(4)]}})
        else:                                               # a bad touch, alone or to add
            touch = bad_touches[rng.integers(len(bad_touches))]
            line = json.dumps({"id": k, "recognize": touch} if kind == 6 else {"id": k, "session": "s", "add": touch})
        out.append(line if line.strip() else "x")
    return out


def test_a_service_process_answers_a_session_and_every_malformed_request(db):
    """A real ``tactrec serve`` process: three touches of the sphere added to a session (each in its
    own sensor frame), ``next``, and ``close``, answered in order with their ids, the sphere best;
    then 1,000 seeded malformed lines, each answered with one error line, after which a good request
    and the session's touches to a new session are still answered as before."""
    touches = _session_touches(db, 3)
    good = _touch("sphere-33", db, 9).to_json()
    lines = [json.dumps({"id": i, "session": "s1", "add": t}) for i, t in enumerate(touches)]
    lines += [json.dumps({"id": "n", "session": "s1", "next": {"radius": 20, "seed": 3}}),
              json.dumps({"id": "c", "session": "s1", "close": True}),
              json.dumps({"id": "after", "session": "s1", "next": {}})]
    bad = _malformed(np.random.default_rng(43), good, 1000)
    tail = [json.dumps({"id": "good", "recognize": good})]
    tail += [json.dumps({"id": f"again-{i}", "session": "s2", "add": t}) for i, t in enumerate(touches)]
    answers = _serve(lines + bad + tail)
    assert len(answers) == len(lines) + len(bad) + len(tail)
    head, fuzz, end = answers[:len(lines)], answers[len(lines):-len(tail)], answers[-len(tail):]
    assert [a["id"] for a in head] == [0, 1, 2, "n", "c", "after"]
    assert all(a["best"] == "sphere-33" and a["session"] == "s1" for a in head[:3])
    assert [a["touches"] for a in head[:3]] == [1, 2, 3] and head[2]["confidence"] >= 0.9
    assert "error" not in head[3] and "hypotheses" in head[3]
    assert head[4] == {"id": "c", "session": "s1", "closed": True, "touches": 3}
    assert "no session 's1' is open" in head[5]["error"]
    assert all(set(a) == {"id", "error"} and a["error"] for a in fuzz), [a for a in fuzz if "error" not in a][:1]
    assert end[0]["id"] == "good" and end[0]["best"] == "sphere-33"
    for a, b in zip(end[1:], head[:3]):                       # the same session again, the same answers
        assert a["best"] == b["best"] and a["touches"] == b["touches"]
        assert np.allclose([r["error"] for r in a["ranking"] if r["error"] is not None],
                           [r["error"] for r in b["ranking"] if r["error"] is not None])


def test_a_service_request_is_the_python_call_and_a_failed_add_changes_nothing(db):
    """A ``recognize`` request answers what Recognizer.recognize gives (but its seconds); a session's
    adds and next what Session.add and Session.next give; a bad add to one session leaves it and
    another as they were (their next answers unchanged)."""
    from tactrec.io.touch import parse_touch

    touches = _session_touches(db, 2)
    good = _touch("cylinder-50", db, 5).to_json()
    with Recognizer(db) as recognizer:
        service = Service(recognizer, seed=7)
        direct = recognizer.recognize(parse_touch(good, "x")).to_json()
        served = service.answer(json.dumps({"id": 1, "recognize": good}))
        assert served.pop("id") == 1
        for out in (served, direct):
            out.pop("seconds")
        assert json.dumps(served) == json.dumps(direct)
        session = recognizer.session()
        for i, t in enumerate(touches):
            data = parse_touch({k: v for k, v in t.items() if k != "sensor2world"}, "x")
            pose = (np.array(t["sensor2world"]["rotation"]), np.array(t["sensor2world"]["translation"]))
            expected = session.add(data, pose).to_json()
            for name in ("a", "b"):
                got = service.answer(json.dumps({"id": i, "session": name, "add": t}))
                assert got["best"] == expected["best"]
                assert got["confidence"] == pytest.approx(expected["confidence"], abs=1e-12)
        want = session.next(radius=20.0, angle=60.0, rng=7).to_json()
        before = [service.answer(json.dumps({"id": 9, "session": n, "next": {"radius": 20}})) for n in ("a", "b")]
        assert all(json.dumps({k: v for k, v in b.items() if k != "id"}) == json.dumps(want) for b in before)
        broken = dict(touches[0], curves=[[[float("nan"), 0.0, 0.0]] + c[1:] for c in touches[0]["curves"]])
        assert "error" in service.answer(json.dumps({"id": 10, "session": "a", "add": broken}).replace("NaN", "1e999"))
        assert "error" in service.answer(json.dumps({"id": 11, "session": "a", "add": dict(touches[0], units="cm")}))
        after = [service.answer(json.dumps({"id": 9, "session": n, "next": {"radius": 20}})) for n in ("a", "b")]
        assert after == before and len(service.sessions["a"].records) == 2


def test_an_add_that_fails_midway_leaves_the_session_as_it_was(db, monkeypatch):
    """Session.add restores the session when it raises after the touch was recorded (here the joint
    fit, made to fail on the third add): the same touches, result and next proposal as before.  A
    number too large for a float, even as an id, and a missed line in other units than the
    session's are error answers, and every answer is strict JSON."""
    touches = _session_touches(db, 3)
    with Recognizer(db) as recognizer:
        service = Service(recognizer)
        for i, t in enumerate(touches[:2]):
            assert "error" not in service.answer(json.dumps({"id": i, "session": "s", "add": t}))
        session = service.sessions["s"]
        before = session.result
        want = service.answer(json.dumps({"id": 2, "session": "s", "next": {"radius": 20}}))

        def broken(*args, **kwargs):
            raise RuntimeError("joint fit failed")

        from tactrec.session.joint import JointFit

        monkeypatch.setattr(JointFit, "__call__", broken)
        got = service.answer(json.dumps({"id": 3, "session": "s", "add": touches[2]}))
        assert "internal error" in got["error"]
        monkeypatch.undo()
        assert len(session.records) == 2 and session.result is before
        assert service.answer(json.dumps({"id": 2, "session": "s", "next": {"radius": 20}})) == want
        assert "too large" in service.answer('{"id": 1e999, "session": "s", "close": true}')["error"]
        missed = {"missed": {"start": [0, 0, 100], "direction": [0, 0, -1], "length": 0.05}, "units": "m"}
        assert "missed line is in 'm'" in service.answer(json.dumps({"id": 4, "session": "s", "add": missed}))["error"]
        assert session.result.missed == 0
