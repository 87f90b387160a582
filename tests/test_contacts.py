"""Touches of single contacts (tactrec.io.contacts, tactrec.engine.contacts, simulate --contacts)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import small_meshes
from tactrec.cli import main
from tactrec.io.touch import load_touch, parse_touch
from tactrec.recognition import Recognizer
from tactrec.simulation import simulate_contacts, truth_pose

from test_bad_input import bad

POINT = [1.0, 2.0, 3.0]


@pytest.fixture(scope="module")
def meshes():
    return small_meshes(coarse=True)


def test_a_file_of_contacts_round_trips(tmp_path, meshes):
    data = simulate_contacts(meshes[0].model, 5, noise=0.1, normal_sd=4.0, rng=3)
    again = parse_touch(json.loads(json.dumps(data.to_json())), "again")
    assert again.kind == "contacts"
    for a, b in zip(again.contacts.__dict__.values(), data.contacts.__dict__.values()):
        np.testing.assert_array_equal(a, b)
    plain = parse_touch({"contacts": [{"point": POINT}, {"point": [4, 5, 6], "normal": [0, 0, 2]}]}, "plain")
    assert not plain.contacts.has_normal[0] and plain.contacts.normals[1].tolist() == [0.0, 0.0, 1.0]
    assert plain.contacts.noise == 0.0                     # no point_sd: read as exact


@pytest.mark.parametrize("contacts, problem", [
    ([], "non-empty list"),
    ([{"normal": [0, 0, 1]}], "must be an object with a 'point'"),
    ([{"point": POINT, "normal": [0, 0, 0]}], "non-zero direction"),
    ([{"point": POINT, "normal_sd_deg": 5}], "without a 'normal'"),
    ([{"point": POINT, "normal": [0, 0, 1], "normal_sd_deg": 0}], "must lie in (0, 90]"),
    ([{"point": POINT, "point_sd": -1}], "'point_sd' must be >= 0"),
    ([{"point": POINT, "force": 3}], "unknown field 'force'"),
    ([{"point": [1, 2, float("nan")]}], "not finite"),
])
def test_bad_contacts_get_one_line(tmp_path, capsys, meshes, contacts, problem):
    path = tmp_path / "touch.json"
    path.write_text(json.dumps({"units": "mm", "contacts": contacts}).replace("NaN", "1e999"))
    problem = "too large" if "not finite" in problem else problem
    bad(capsys, ["recognize", path, "--models", "sphere-33"], path, problem)


def test_contacts_too_few_or_on_one_line_are_refused(tmp_path, capsys):
    path = tmp_path / "two.json"
    path.write_text(json.dumps({"units": "mm", "contacts": [{"point": [0, 0, 0], "normal": [0, 0, 1]},
                                                             {"point": [5, 0, 0], "normal": [0, 0, 1]}]}))
    bad(capsys, ["recognize", path, "--models", "sphere-33"], path, "at least 3 are needed")
    line = tmp_path / "line.json"
    line.write_text(json.dumps({"units": "mm", "contacts": [{"point": [k, 0, 0], "normal": [0, 0, 1]}
                                                             for k in range(4)]}))
    bad(capsys, ["recognize", line, "--models", "sphere-33"], line, "without enough spread")
    both = tmp_path / "both.json"
    both.write_text(json.dumps({"contacts": [{"point": POINT}], "outward": [0, 0, 1]}))
    bad(capsys, ["recognize", both, "--models", "sphere-33"], both, "takes no 'outward'")


def test_simulate_contacts_writes_a_touch_that_loads(tmp_path, capsys):
    out = tmp_path / "c.json"
    assert main(["simulate", "sphere-33", "--contacts", "7", "--noise", "0.05", "--normal-sd", "3", "--out",
                 str(out), "--quiet"]) == 0
    data = load_touch(out)
    assert data.kind == "contacts" and len(data.contacts) == 7
    assert np.all(data.contacts.normal_sd == 3.0) and np.all(data.contacts.point_sd == 0.05)
    bad(capsys, ["simulate", "sphere-33", "--normal-sd", "3", "--out", tmp_path / "x.json"], "simulate",
        "--normal-sd is for contacts")


def test_contacts_recognise_and_pose_the_small_meshes(meshes):
    """Ten contacts (0.05 mm, normals 3 degrees) on three small meshes of distinct shapes (the capsule,
    the brick, the ring), seven or six each: the right model at least 17 times in 20, never another
    one surely, and the right answer's pose puts the true contacts within 1 mm of the surface they
    came from."""
    meshes = meshes[1:]
    right = sure_wrong = 0
    with Recognizer(meshes) as recognizer:
        for k in range(20):
            entry = meshes[k % 3]
            data = simulate_contacts(entry.model, 10, noise=0.05, normal_sd=3.0, rng=np.random.default_rng([7, k]))
            result = recognizer.recognize(data)
            if result.best == entry.name:
                right += 1
                r = result.registration
                truth = np.asarray(data.meta["truth"]["contacts"])
                Rt, tt = truth_pose(data)
                seen = (truth - tt) @ Rt                      # the true contacts in the data's frame
                moved = seen @ r.rotation.T + r.translation
                assert np.max(np.abs(entry.model.distance(moved))) < 1.0
            elif result.best is not None and result.confidence >= 0.95:
                sure_wrong += 1
    assert right >= 17, right
    assert sure_wrong == 0


def test_three_or_four_contacts_on_a_thin_wall_find_their_side(monkeypatch):
    """A tube whose wall (2 mm) is thinner than the places' cells: 20 seeded touches of three or four
    contacts (0.1 mm, normals 5 degrees), each recognised with the tube alone, are posed (not rejected) in
    18 or more.  With one place a cell, one side of the wall has no place in many cells, and then no pose
    the search tries agrees with the contacts' normals (6 of 20 are rejected so).  At a quarter of the
    places' budget, so that it takes seconds: the cells are larger, the wall as thin against them."""
    import trimesh

    from tactrec.engine import contacts as stage
    from tactrec.recognition import ModelEntry
    from tactrec.surfaces.mesh import MeshModel
    from tactrec.tables import CurvatureTable

    monkeypatch.setattr(stage, "PLACES", stage.PLACES // 4)
    mesh = trimesh.creation.annulus(r_min=28.0, r_max=30.0, height=60.0, sections=96)
    model = MeshModel(mesh.vertices, mesh.faces, name="tube", units="mm")
    posed = 0
    with Recognizer([ModelEntry(model, CurvatureTable(model.table_samples()))]) as recognizer:
        for k in range(20):
            data = simulate_contacts(model, 3 + k % 2, noise=0.1, normal_sd=5.0, rng=np.random.default_rng([9, k]))
            posed += recognizer.recognize(data).ranking[0].ok
    assert posed >= 18, posed


def test_contacts_added_one_at_a_time_are_no_surer_than_given_at_once(meshes):
    """Six contacts of each of the three meshes, added to a session one at a time, end on the same
    answer as one touch of all six, and the session is no surer against ``unknown`` than that touch
    (within a factor of ten): the contacts are one search, and counting each as a touch of its own
    would leave ``unknown`` about ninety times less likely with every contact."""
    from tactrec.io.touch import TactileData

    meshes = meshes[1:]
    with Recognizer(meshes) as recognizer:
        for k, entry in enumerate(meshes):
            data = simulate_contacts(entry.model, 6, noise=0.05, normal_sd=3.0, rng=np.random.default_rng([11, k]))
            once = recognizer.recognize(data)
            session, c = recognizer.session(), data.contacts
            for i in range(len(c)):
                one = c.rows(slice(i, i + 1))
                result = session.add(TactileData.from_contacts(one, units=data.units, source=f"contact {i + 1}"))
            assert result.best == once.best == entry.name
            assert result.unknown >= 0.1 * once.unknown, (entry.name, result.unknown, once.unknown)


def test_the_contacts_screen_keeps_what_scoring_every_pose_keeps(meshes, monkeypatch):
    """The screen of triangles of places stops a pose's sum once it cannot be among the best kept; on
    the egg and the ring, in many small parts (so that the cut applies from the second on), it keeps the
    same poses with the same scores as scoring every pose in full in one part, for two touches each."""
    from tactrec.engine import contacts as stage

    for entry in (meshes[0], meshes[3]):
        P, N, reach = stage._places(entry.model)
        for k in range(2):
            c = simulate_contacts(entry.model, 6, noise=0.05, normal_sd=3.0, rng=np.random.default_rng([5, k])).contacts
            xa = np.ascontiguousarray(stage.tangent_points(c.points, c.normals, c.normal_sd, 0.05))
            tri = stage.triangles(c.points, 1)[0]
            tol = 2.0 * reach + 0.3
            args = (entry.model.distance_field, P, N, c.points, xa, c.normals, c.normal_sd, tri, tol)
            monkeypatch.setattr(stage, "FIELD_KEEP", 40)
            monkeypatch.setattr(stage, "CHUNK", 10**12)
            full = stage._triangle_screen(*args)
            monkeypatch.setattr(stage, "CHUNK", 500)
            cut = stage._triangle_screen(*args)
            assert full[3] == cut[3] > 40 * 20, (entry.name, k, full[3])
            for a, b in zip(full[:3], cut[:3]):
                np.testing.assert_array_equal(a, b)
            assert len(full[2]) == 40


def test_next_sends_a_session_of_contacts_a_contact(meshes):
    """A session of contacts on the capsule, the brick or the ring (random ones until some model is posed)
    is sent a contact, not curves to trace: an approach line that starts outside the object.  The probe
    follows two such lines on the true object, recording a contact where one meets it or a line that met
    nothing; most meet it, and each session ends on the right model."""
    from tactrec.bench.contacts import followed
    from tactrec.io.session import MissedLine
    from tactrec.io.touch import TactileData
    from tactrec.session.result import Hypothesis

    meshes = meshes[1:]
    right = met = 0
    with Recognizer(meshes) as recognizer:
        for k, entry in enumerate(meshes):
            data = simulate_contacts(entry.model, 6, noise=0.05, normal_sd=3.0, rng=np.random.default_rng([13, k]))
            truth = Hypothesis("truth", *truth_pose(data), 1.0, 0.0, np.zeros(0), ())
            session, c = recognizer.session(), data.contacts
            for i in range(6):                          # at random until some model is posed
                one = c.rows(slice(i, i + 1))
                if session.add(TactileData.from_contacts(one, units="mm", source=f"contact {i + 1}")).ranking:
                    break
            for i in range(2):
                proposal = session.next(radius=40.0, rng=k)
                if proposal.contact is None:
                    break
                out = proposal.to_json()
                assert "directions" not in out and out["approach"]["length"] > 0
                start = truth.rotation @ proposal.approach.start + truth.translation
                assert entry.model.planes(start[None])[0][0] > 0            # starts outside the object
                found = followed(proposal, entry.model, truth, 0.05, 3.0, np.random.default_rng([17, k, i]))
                if isinstance(found, MissedLine):
                    session.add_miss(found)
                else:
                    met += 1
                    session.add(TactileData.from_contacts(found, units="mm", source=f"next {i + 1}"))
            right += session.result.best == entry.name
    assert right == 3 and met >= 4, (right, met)


def test_bench_contacts_split_over_runs_gives_the_sessions_of_one_run(tmp_path, monkeypatch):
    """``--first-instance`` runs the later instances alone, so two runs on two machines give, between
    them, each session of one run (each session is seeded by its scan and instance alone)."""
    from tactrec.bench import contacts

    def session(task):                                   # the seeded draws a session starts from
        m, i, seed = task[:3]
        draw = contacts.instance_rng(seed, m, i).random()
        return {"model": contacts._names()[m], "instance": i, "strategy": task[6],
                "steps": [{"best": None, "confidence": draw, "unknown": 0.0, "seconds": 0.0}]}

    monkeypatch.setattr(contacts, "_session", session)
    whole = contacts.run(out=tmp_path / "whole", instances=3, jobs=1, quiet=True)
    late = contacts.run(out=tmp_path / "late", instances=3, first=2, jobs=1, quiet=True)
    early = contacts.run(out=tmp_path / "early", instances=2, jobs=1, quiet=True)
    records = lambda table: table["sets"]["fig11 random"]["records"]            # noqa: E731
    assert records(early) + records(late) == records(whole)
    assert {r["instance"] for r in records(late)} == {2} and "instances 2 to 2" in late["text"]
