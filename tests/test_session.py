"""Sessions of several touches (tactrec.session), where to touch next (tactrec.proposal), their files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from tactrec.bench.multi_touch import STRATEGIES
from tactrec.cli import main
from tactrec.errors import InputError
from tactrec.io.session import SessionTouch, load_session, save_session
from tactrec.recognition import Recognizer
from tactrec.proposal import leading_hypotheses
from tactrec.registration import Outcome
from tactrec.session import STAGES, STARTS
from tactrec.simulation import random_rigid_motion, sensor_to_world, simulate_random_touch

NOISY = dict(points=41, spacing=0.3, angle=60.0, noise=0.03, noise_kind="gaussian", outward=False)
#: the hard touches of ``bench multi-touch``: 12 mm curves 30 degrees apart, noise 0.05 mm, no outward side
HARD = dict(points=41, spacing=0.3, angle=30.0, noise=0.05, noise_kind="gaussian", outward=False)


#: the half-turns about the axes, the rotations that map a centred, axis-aligned ellipsoid or box onto itself
SYMMETRIES = [np.diag(d) for d in ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1))]


def _rotation_error_deg(A: np.ndarray, B: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(A.T @ B) - 1) / 2, -1, 1))))


def test_a_session_finds_the_world_to_model_pose(small):
    """Eight seeded sessions of three noisy touches (random sensor frames, the object in a random
    world pose the models never see): the best model is the touched one, with confidence >= 0.95,
    each touch's error at the noise (below 0.05 mm), no touch reported slipped, and on the egg and
    the brick (poses unique up to their half-turn symmetries) the joint pose within 2 degrees of
    the truth and the contacts within 0.5 mm."""
    with Recognizer(small) as recognizer:
        for k in range(8):
            entry = small[k % len(small)]
            Rw, tw = random_rigid_motion(np.random.default_rng((5, k)), extent=300.0)
            session = recognizer.session()
            for i in range(3):
                touch = simulate_random_touch(entry.model, rng=np.random.default_rng((6, k, i)), **NOISY)
                result = session.add(touch, sensor_to_world(touch, (Rw, tw)))
            assert result.best == entry.name and result.confidence >= 0.95 and result.slipped == ()
            h = result.hypothesis(entry.name)
            assert h.per_touch.shape == (3,) and np.all(h.per_touch < 0.05)
            world = np.array([w.contact if w.contact is not None else f.geometry.contact
                              for w, f in zip(session.world, session.features)])
            truth = (world - tw) @ Rw                                              # world -> model
            found = world @ h.rotation.T + h.translation
            if entry.name in ("egg", "brick"):      # centred, axis-aligned: unique up to half-turns about the axes
                S = min(SYMMETRIES, key=lambda S: _rotation_error_deg(h.rotation, S @ Rw.T))
                assert _rotation_error_deg(h.rotation, S @ Rw.T) < 2.0
                assert np.max(np.linalg.norm(found - truth @ S.T, axis=1)) < 0.5


def _add_touches(session, model, pose, count: int, key: int) -> None:
    """Add ``count`` noisy touches of ``model`` (seeded by ``key``), the object at world ``pose``."""
    for i in range(count):
        touch = simulate_random_touch(model, rng=np.random.default_rng((key, i)), **NOISY)
        session.add(touch, sensor_to_world(touch, pose))


def test_a_slipped_touch_is_reported_not_averaged(small):
    """Three touches of the egg and then a fourth after the object moved (another world pose):
    the fourth is reported slipped, the egg stays best and its pose fits the first three at the
    noise."""
    entry = small[0]
    Rw, tw = random_rigid_motion(np.random.default_rng((9,)), extent=300.0)
    Rm, tm = random_rigid_motion(np.random.default_rng((10,)), extent=300.0)
    with Recognizer(small) as recognizer:
        session = recognizer.session()
        _add_touches(session, entry.model, (Rw, tw), 3, 11)
        touch = simulate_random_touch(entry.model, rng=np.random.default_rng((11, 3)), **NOISY)
        result = session.add(touch, sensor_to_world(touch, (Rm, tm)))
    assert result.slipped == (3,)
    assert result.best == entry.name
    h = result.hypothesis(entry.name)
    assert np.all(h.per_touch[:3] < 0.05) and h.per_touch[3] > 0.2


def test_next_proposes_an_approach_line_from_outside_every_hypothesis(small):
    """Ten seeded one-touch sessions on the capsule and the ring (flat and round patches alike):
    where a proposal is made, its line starts outside every leading hypothesis' surface, runs along a
    unit direction, and its expected contact lies on the line within the radius (and the standoff) of
    the touch; its normal is unit and its gain positive; where none is made, one hypothesis holds 99%
    of the probability (one that holds 99% of the models' but leaves unknown more gets a touch to
    confirm it)."""
    from tactrec.proposal import STANDOFF

    models = {e.name: e.model for e in small}
    with Recognizer(small) as recognizer:
        for k in range(10):
            entry = small[1 + k % 2]
            Rw, tw = random_rigid_motion(np.random.default_rng((12, k)), extent=300.0)
            touch = simulate_random_touch(entry.model, rng=np.random.default_rng((13, k)), **dict(NOISY, points=21))
            session = recognizer.session()
            result = session.add(touch, sensor_to_world(touch, (Rw, tw)))
            proposal = session.next(radius=20.0, rng=k)
            if proposal.contact is None:
                assert result.confidence >= 0.99
                continue
            line = proposal.approach
            assert abs(np.linalg.norm(line.direction) - 1.0) < 1e-9 and line.length > 0
            c0 = session.features[0].geometry.contact if session.world[0].contact is None else session.world[0].contact
            assert np.linalg.norm(proposal.contact - c0) <= 20.0 + 2 * STANDOFF * 20.0
            along = (proposal.contact - line.start) @ line.direction
            assert -1e-9 <= along <= line.length + 1e-9
            assert np.linalg.norm(line.start + along * line.direction - proposal.contact) < 1e-6
            assert abs(np.linalg.norm(proposal.normal) - 1.0) < 1e-9 and proposal.gain > 0
            for name, _ in proposal.hypotheses:
                h = result.hypothesis(name)
                x = h.scale * line.start @ h.rotation.T + h.translation
                assert models[name].planes(x[None])[0][0] > 0
            assert set(proposal.to_json()["approach"]) == {"start", "direction", "length"}


def test_next_sends_the_line_through_a_touched_point_when_no_pose_fits(small):
    """Eight seeded one-touch sessions of the egg against a database of the brick and the ring alone,
    whose poses cannot fit it: the line runs through the touch's point farthest from its contact
    (the data say the object is there) along the touch's own normal, on the side the leading poses
    vote for and starting outside one of them (the poses that do not fit say nothing of where the
    object is not), so it meets the egg itself, at that point or before; the first curve runs away
    from the contact and the curves lie across the line."""
    from tactrec.session import Hypothesis
    from tactrec.missed import first_hit

    egg = small[0]
    models = {e.name: e.model for e in small}
    located = 0
    with Recognizer(small[2:]) as recognizer:
        for k in range(8):
            Rw, tw = random_rigid_motion(np.random.default_rng((14, k)), extent=300.0)
            touch = simulate_random_touch(egg.model, rng=np.random.default_rng((15, k)), **dict(NOISY, points=31))
            session = recognizer.session()
            result = session.add(touch, sensor_to_world(touch, (Rw, tw)))
            leading = leading_hypotheses(result)
            proposal = session.next(radius=20.0, rng=k)
            if any(session.fitted_at(h.error, [0]) for h in leading) or proposal.contact is None:
                continue
            located += 1
            x = session.features[0].points
            contact = session.world[0].contact if session.world[0].contact is not None else \
                session.features[0].geometry.contact
            gap = np.linalg.norm(x - contact, axis=1)
            line = proposal.approach
            assert np.min(np.linalg.norm(x - proposal.contact, axis=1)) < 1e-9           # a touched point
            assert gap[np.argmin(np.linalg.norm(x - proposal.contact, axis=1))] >= np.max(gap) - 1.0
            off = proposal.contact - line.start
            assert np.linalg.norm(off - (off @ line.direction) * line.direction) < 1e-9   # on the line
            assert abs(line.direction @ session.features[0].geometry.normal) > 1.0 - 1e-9
            assert any(models[h.model].planes((h.scale * line.start @ h.rotation.T + h.translation)[None])[0][0] > 0
                       for h in leading)
            truth = Hypothesis("egg", Rw.T, -Rw.T @ tw, 1.0, 0.0, np.zeros(0), ())
            hit = first_hit(egg.model, truth, line, 0.3)
            assert hit is not None and (hit - line.start) @ line.direction <= off @ line.direction + 0.3
            assert np.allclose(proposal.directions @ line.direction, 0.0, atol=1e-9)
            assert (proposal.directions[0] @ (proposal.contact - contact)) > 0
            out = proposal.to_json()
            assert out["gain"] > 0 and [h["model"] for h in out["hypotheses"]] == [h.model for h in leading]
    assert located >= 4


def test_session_files_round_trip_and_bad_ones_are_one_line(tmp_path, capsys):
    """A session written and read back keeps its touches and poses; a rotation that is not one, a
    touch without curves or with NaN, and an empty list each exit 2 with one line naming the file
    and the touch."""
    from tactrec.surfaces import load_model

    model = load_model("sphere-33")
    touches = []
    for i in range(2):
        t = simulate_random_touch(model, rng=i, points=21, spacing=0.5)
        touches.append(SessionTouch(t, *sensor_to_world(t, random_rigid_motion(i, extent=10.0))))
    path = tmp_path / "s.json"
    save_session(touches, path)
    back = load_session(path)
    assert len(back) == 2
    for a, b in zip(touches, back):
        assert np.allclose(a.rotation, b.rotation) and np.allclose(a.in_world().points, b.in_world().points)
    good = json.loads(path.read_text())
    bad = {
        "not-a-rotation": dict(good, touches=[dict(good["touches"][0], sensor2world={
            "rotation": [[2, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0, 0, 0]})]),
        "no-curves": dict(good, touches=[{"contact": [0, 0, 0]}]),
        "empty": dict(good, touches=[]),
    }
    for name, obj in bad.items():
        p = tmp_path / f"{name}.json"
        p.write_text(json.dumps(obj))
        assert main(["recognize", str(p), "--models", "sphere-33", "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(p) in err[0], err
    nan = path.read_text().replace(str(good["touches"][1]["curves"][0][0][0]), "NaN", 1)
    p = tmp_path / "nan.json"
    p.write_text(nan)
    assert main(["next", str(p), "--models", "sphere-33", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "touch 2" in err[0]
    with pytest.raises(InputError):
        load_session(tmp_path / "missing.json")


def test_a_touch_the_estimator_refuses_leaves_the_session_as_it_was():
    """A second touch whose curves are one curve three times (tangent at the contact) raises one
    InputError and changes nothing: the session keeps one touch and its result, and a good second
    touch is then added as if the bad one had never come."""
    import dataclasses

    from tactrec.database import build_entries

    db = build_entries(["ellipsoid", "sphere-33"])
    touches = [simulate_random_touch(db.entries[0].model, rng=np.random.default_rng((40, i)), **NOISY)
               for i in range(2)]
    bad = dataclasses.replace(touches[1], curves=(touches[1].curves[0],) * 3)
    runs = []
    for with_bad in (False, True):
        with Recognizer(db.entries) as recognizer:
            session = recognizer.session()
            first = session.add(touches[0])
            if with_bad:
                with pytest.raises(InputError, match="tangent"):
                    session.add(bad)
                assert len(session.records) == 1
                assert session.result is first
            result = session.add(touches[1])
            runs.append((result.best, result.probabilities, [h.per_touch.tobytes() for h in result.ranking]))
    assert runs[0] == runs[1]


def test_recognize_and_next_on_a_session_file(tmp_path, capsys):
    """The command line on a two-touch session of the ellipsoid among the closed-form surfaces: one
    result with ``touches`` 2, a single touch's keys (contact, curvatures, each entry's location),
    per-touch errors and probabilities summing to 1 with unknown's; ``next --json`` gives the interface's keys."""
    from tactrec.surfaces import load_model

    model = load_model("ellipsoid")
    Rw, tw = random_rigid_motion(3, extent=5.0)
    touches = []
    for i in range(2):
        t = simulate_random_touch(model, rng=20 + i, points=31, spacing=0.02, noise=0.001, noise_kind="gaussian")
        touches.append(SessionTouch(t, *sensor_to_world(t, (Rw, tw))))
    path = tmp_path / "s.json"
    save_session(touches, path)
    assert main(["recognize", str(path), "--models", "closed-form", "--json", "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["best"] == "ellipsoid" and out["touches"] == 2
    accepted = [r for r in out["ranking"] if r["error"] is not None]
    assert abs(sum(r["probability"] for r in accepted) + out["unknown"] - 1.0) < 1e-9 and out["unknown"] < 0.05
    assert all(len(r["per_touch_error"]) == 2 and len(r["location"]) == 3 for r in accepted)
    assert len(out["contact"]) == 3 and len(out["curvatures"]) == 2
    assert main(["next", str(path), "--models", "closed-form", "--json", "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"contact", "gain", "hypotheses"} <= set(out)


def test_next_measures_a_difference_after_refitting_the_pose_the_touches_leave_free():
    """The separation ``next`` weighs (tactrec.proposal): earlier points on a box's top face pin its
    height and tilt but leave it free to slide in the plane.  A predicted touch on a side face 2 mm
    out is absorbed by the slide (under one standard error); the same touch with the earlier
    touches pinning every motion, and a touch on the top face 1 mm up, are told apart by tens of
    standard errors; the excess distance is the folded normal's mean less the half-normal's."""
    import trimesh
    from scipy import stats

    from tactrec.proposal.gain import excess, information, separation
    from tactrec.session import Hypothesis
    from tactrec.surfaces.mesh import MeshModel

    box = trimesh.creation.box(extents=(40.0, 30.0, 20.0)).subdivide().subdivide().subdivide()
    model = MeshModel(box.vertices, box.faces, name="box", units="mm")
    g = np.linspace(-5.0, 5.0, 11)
    earlier = np.array([[x, y, 10.0] for x in g for y in g])                    # on the top face
    pose = np.concatenate([np.eye(3), np.zeros((3, 1))], axis=1)
    h = Hypothesis("box", np.eye(3), np.zeros(3), 1.0, 0.0, np.zeros(1), (True,))
    H0 = information(model, pose, 1.0, earlier)
    z = np.linspace(-6.0, 6.0, 41)
    side = np.stack([np.full_like(z, 22.0), np.linspace(-3.0, 3.0, 41), z], axis=1)      # the side face, 2 mm out
    top = np.stack([np.linspace(-8.0, 8.0, 41), np.linspace(-4.0, 4.0, 41), np.full_like(z, 11.0)], axis=1)
    sigma = 0.05
    slid, lifted = separation(model, h, H0, np.stack([side, top]), sigma, len(earlier))
    pinned = separation(model, h, 1e12 * np.eye(6), side[None], sigma, len(earlier))[0]
    assert slid < 1.0 and lifted > 20.0 and pinned > 20.0
    a = np.array([0.0, 0.3, 1.0, 4.0]) * sigma
    folded = np.array([stats.foldnorm.mean(x / sigma, scale=sigma) for x in a])
    assert np.allclose(excess(a, sigma), folded - sigma * np.sqrt(2 / np.pi), atol=1e-12)


def test_next_predicts_a_touch_up_to_the_edge_it_crosses():
    """A predicted touch (tactrec.proposal.predict.predicted) on a box's top face 3 mm from an edge, one
    curve across the edge: its points lie on the top face up to the edge and are predicted there,
    none past it; the curves along the face are predicted whole; at the edge itself the half on
    the face is; a touch whose curves keep less than KEPT of their points (across a 2 mm slab) is
    not predicted; a kept point's refit residual counts and a dropped one's does not."""
    import trimesh

    from tactrec.proposal.gain import separation
    from tactrec.proposal.predict import KEPT, predicted
    from tactrec.session import Hypothesis
    from tactrec.surfaces.mesh import MeshModel

    box = trimesh.creation.box(extents=(40.0, 30.0, 20.0)).subdivide().subdivide()
    model = MeshModel(box.vertices, box.faces, name="box", units="mm")
    h = Hypothesis("box", np.eye(3), np.zeros(3), 1.0, 0.0, np.zeros(1), (True,))
    along = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])   # two along the edge, one across
    x, kept = predicted(model, h, np.array([17.0, 0.0, 10.0]), along, points=41, spacing=0.3)
    x, kept = x.reshape(3, 41, 3), kept.reshape(3, 41)
    assert kept[:2].all() and np.allclose(x[:2, :, 2], 10.0, atol=1e-9)
    across = x[2][kept[2]]
    assert np.all(across[:, 0] <= 20.0 + 1e-9) and np.allclose(across[:, 2], 10.0, atol=1e-9)
    assert 30 <= kept[2].sum() <= 31 and kept[2, :20].all()          # 3 mm to the edge: 10 steps, 0.3 mm apart
    half = predicted(model, h, np.array([20.0, 0.0, 10.0]), along, points=41, spacing=0.3)
    assert half is not None and half[1].reshape(3, 41)[2, :21].all()   # at the edge: the half on the face
    slab = trimesh.creation.box(extents=(40.0, 2.0, 20.0)).subdivide().subdivide()
    thin = MeshModel(slab.vertices, slab.faces, name="slab", units="mm")
    across = np.array([[0.0, 1.0, 0.0], [0.5, np.sqrt(0.75), 0.0], [-0.5, np.sqrt(0.75), 0.0]])
    assert 2.0 / 0.3 + 1 < KEPT * 41                                 # the slab's 2 mm top keeps 7 points of 41
    assert predicted(thin, h, np.array([0.0, 0.0, 10.0]), across, points=41, spacing=0.3) is None
    off = np.stack([np.linspace(-5.0, 5.0, 41), np.zeros(41), np.full(41, 10.5)], axis=1)[None]
    part = np.zeros((1, 41), dtype=bool)
    part[0, :5] = True
    pinned = 1e12 * np.eye(6)
    assert separation(model, h, pinned, off, 0.05, 100, part)[0] > 3.0
    assert separation(model, h, pinned, off, 0.05, 100, part)[0] < separation(model, h, pinned, off, 0.05, 100)[0]


def test_next_proposes_the_widest_span_among_places_of_saturated_gain():
    """The choice among scored places (tactrec.proposal): gains within TIE of the entropy of the best
    count as equal and the place farthest from every earlier contact wins; a place that gains
    clearly less is not taken however far it lies, and with one place that is the one."""
    from tactrec.proposal import TIE, choose

    contacts = np.array([[0.0, 0, 0], [30.0, 0, 0]])
    entropy = 1.0

    def place(gain, x):
        return (gain, np.array([x, 8.0, 0.0]), np.array([0.0, 0, 1]), np.eye(3))

    best, near_far, low_far = place(1.0, 2.0), place(1.0 - 0.5 * TIE, 15.0), place(1.0 - 2 * TIE, 60.0)
    chosen = choose([best, near_far, low_far], contacts, entropy)
    assert chosen is near_far                     # 15 mm from both contacts, the best place 8 mm from one
    assert choose([best, low_far], contacts, entropy) is best
    assert choose([low_far], contacts, entropy) is low_far and choose([], contacts, entropy) is None


def test_a_new_touch_whose_own_search_fitted_nothing_rules_no_model_out(small):
    """Step 5's models: two noisy touches of the egg.  The second touch's own errors rule out the
    models beyond its limits only while its own search fitted some model; once every model's own
    error is far beyond what its noise allows (a search that missed everywhere), every model whose
    joint pose does not fit every touch is searched again, the ones it ruled out included.  The
    second touch's own search is taken over every model (a session searches a later touch among
    its standing models first), so that its errors have models to rule out."""
    import dataclasses

    entry = small[0]
    with Recognizer(small) as recognizer:
        session = recognizer.session()
        _add_touches(session, entry.model, random_rigid_motion(np.random.default_rng((14,)), extent=300.0), 2, 15)
        whole = recognizer.recognize(session.records[-1].world)
    slipped = set(session.result.slipped)

    def with_own(own):
        """The session's touches, the last one's own search being ``own``."""
        last = dataclasses.replace(session.records[-1], own=own)
        return dataclasses.replace(session.touches, records=session.records[:-1] + (last,))

    def failing(name):
        h = session.result.hypothesis(name)
        return h is None or not all(c for i, c in enumerate(h.consistent) if i not in slipped)

    from tactrec.session.add import Add

    def step_5(touches):
        """The models step 5 would search after this add, over ``touches``."""
        add = Add(recognizer, touches, session.misses, session.joint, search_budget=1.0)
        add.touches, add.result = touches, session.result
        return set(add.unexplained(slipped))

    own, touches = whole, with_own(whole)
    limit = touches.limits()[-1]
    searched = step_5(touches)
    assert searched == {r.model for r in own.ranking if r.ok and r.error / r.scale <= limit and failing(r.model)}
    # the same touch as if its own search had missed everywhere: ten times every error
    missed = dataclasses.replace(own, ranking=[dataclasses.replace(r, error=10 * r.error) if r.ok else r
                                                for r in own.ranking])
    widened = step_5(with_own(missed))
    deferred = {r.model for r in own.ranking if r.outcome is Outcome.DEFERRED}
    assert widened == {r.model for r in own.ranking if r.ok and failing(r.model)} | {m for m in deferred if failing(m)}
    assert searched <= widened
    assert any(failing(r.model) and r.ok and r.error / r.scale > limit for r in own.ranking) or deferred, \
        "the touch leaves no model beyond its limit to rule out: the check above is vacuous"


def test_a_sessions_fits_are_the_same_in_worker_processes(scans):
    """Two sessions of three hard touches (noise 0.05 mm, 12 mm curves 30 degrees apart, no outward
    side) on scans searched under a small budget, so that adds search again with the other touches
    in the score (step 5) and fit the models again from that search's poses: in this process and
    in two worker processes, the same hypotheses, errors and probabilities."""
    runs, searched, stages = {}, [], []
    for workers in (1, 2):
        with Recognizer(scans.entries, workers=workers, budget=30_000) as recognizer:
            out = []
            for k, j in ((1, 10), (2, 6)):
                entry = scans.entries[k]
                session = recognizer.session()
                pose = random_rigid_motion(np.random.default_rng((30, k, j)), extent=300.0)
                for i in range(3):
                    touch = simulate_random_touch(entry.model, rng=np.random.default_rng((32, k, j, i)), **HARD)
                    result = session.add(touch, sensor_to_world(touch, pose))
                    searched.append(len(result.searched) - 1)
                    stages.append((result.stages, result.seconds, len(result.searched) - 1))
                    out.append((result.best, result.slipped, result.probabilities,
                                [(h.model, h.error, h.rotation.tobytes(), h.per_touch.tobytes()) for h in result.ranking]))
            runs[workers] = out
    assert runs[1] == runs[2]
    # a fit after a search of step 5 is compared, and so is a search started after another in one add
    assert max(searched) >= 1, "no add ran a search of step 5: its refits go unchecked"
    assert max(searched) <= 2 * STARTS                 # two passes, each from at most STARTS touches
    # each add's seconds by stage: the parts add up to no more than the whole, the own search always
    # runs, and a stage of step 5 has seconds exactly when the add ran a search of it
    for parts, seconds, extra in stages:
        assert set(parts) == set(STAGES) and parts["own"] > 0.0 and parts["joint"] > 0.0
        assert sum(parts.values()) <= seconds * (1 + 1e-9)
        assert (parts["context"] > 0.0) == (extra > 0)


def test_multi_touch_summary_reports_the_add_cost_per_session_size():
    """The add-cost ratios are per added touch, pooled and per session size, and a session that
    stopped early adds nothing to the later sizes."""
    from tactrec.bench.multi_touch_report import summary

    def step(correct, confidence, seconds, own):
        return {"best": "a" if correct else "b", "correct": correct, "confidence": confidence,
                "seconds": seconds, "own_seconds": own, "slipped": []}

    long = [step(True, 0.5, 1.0, 1.0), step(True, 0.9, 3.0, 1.0), step(True, 0.99, 8.0, 2.0),
            step(True, 1.0, 1.0, 1.0), step(True, 1.0, 6.0, 2.0)]
    short = [step(False, 0.4, 2.0, 2.0), step(True, 1.0, 2.0, 2.0)]
    rows = [{"random": long, "next": short}, {"random": long, "next": long}]
    s = summary(rows, STRATEGIES, 5)
    by_n = s["next"]["add_over_own_by_touches"]
    assert [b["adds"] for b in by_n] == [2, 1, 1, 1]
    assert by_n[0]["median"] == pytest.approx(2.0)          # ratios 1 and 3
    assert by_n[1]["median"] == pytest.approx(4.0) and by_n[3]["median"] == pytest.approx(3.0)
    assert s["next"]["add_over_own"]["median"] == pytest.approx(3.0)   # ratios 1, 3, 4, 1, 3
    assert s["random"]["add_over_own_by_touches"][0]["adds"] == 2
    assert s["next"]["per_touches"][0]["accuracy_percent"] == pytest.approx(50.0)
    assert s["next"]["mean_touches_to_0.99"] == pytest.approx(2.5)
    parts = s["random"]["add_stages"]                       # no stages recorded: nothing counted
    assert all(parts[k]["adds"] == 0 and parts[k]["over_own_median"] is None for k in STAGES)


def test_a_session_has_decided_when_it_is_right_and_sure_and_stays_right():
    """The bench's measure of when a session has decided: its answer right at confidence >= 0.95 and
    right at every later touch.  A session sure of the right answer that a later touch turns wrong
    had not decided then; 0.99, which one perfect touch in the open world does not reach, is kept
    beside it; ``next`` against random places is compared by both."""
    from tactrec.bench.multi_touch_report import summary, text

    def step(correct, confidence):
        return {"best": "a" if correct else "b", "correct": correct, "confidence": confidence, "seconds": 1.0,
                "own_seconds": 1.0, "slipped": []}

    proposed = [step(False, 0.6), step(True, 0.96), step(True, 0.97), step(True, 0.995), step(True, 1.0)]
    random = [step(True, 0.96), step(False, 0.97), step(True, 0.96), step(True, 0.96), step(True, 0.96)]
    s = summary([{"next": proposed, "random": random}], STRATEGIES, 5)
    assert s["next"]["mean_touches_to_right"] == 2 and s["random"]["mean_touches_to_right"] == 3
    assert s["next"]["mean_touches_to_0.99"] == 4 and s["random"]["mean_touches_to_0.99"] == 5
    pair = s["next_against_random"]
    assert (pair["extra_next"], pair["extra_random"], pair["next_earlier"]) == (1, 2, 1)
    assert (pair["at_0.99"]["extra_next"], pair["at_0.99"]["extra_random"]) == (3, 4)
    table = text({"seed": 0, "touches": 5, "strategies": STRATEGIES, "summary": {"s": s}})
    assert "| s | right at 0.95 | 1.00 | 2.00 |" in table and "| s | 0.99 | 3.00 | 4.00 |" in table


def test_multi_touch_keeps_each_strategys_sessions_apart():
    """Each strategy's sessions are saved apart and merged into one row per session; a run of one
    strategy reports that strategy alone, its first touches the cost reference."""
    from tactrec.bench.multi_touch import code_hash, merged
    from tactrec.bench.multi_touch_report import summary

    def step(correct, seconds):
        return {"best": "a" if correct else "b", "correct": correct, "confidence": 0.9, "seconds": seconds,
                "own_seconds": 1.0, "slipped": []}

    parts = [{"set": "s", "model": "a", "instance": 0, "next": [step(True, 4.0), step(True, 3.0)]},
             {"set": "s", "model": "a", "instance": 1, "next": [step(False, 2.0)]},
             {"set": "s", "model": "a", "instance": 0, "random": [step(False, 4.0)]}]
    rows = merged(parts)
    assert len(rows) == 2 and set(rows[0]) == {"set", "model", "instance", "next", "random"}
    s = summary(rows[1:] + [{k: v for k, v in rows[0].items() if k != "random"}], ("next",), 5)
    assert set(s) == {"next", "first_touch_seconds", "sessions"}
    assert s["next"]["add_ratio_of_medians"] == pytest.approx(3.0 / 3.0)      # first touches 2 and 4 s
    assert s["next"]["per_touches"][1]["accuracy_percent"] == pytest.approx(50.0)
    assert code_hash("random") != code_hash("next")        # random places never run the proposal code


def test_multi_touch_summary_says_where_the_adds_time_goes():
    """The stage breakdown: per stage, the adds that ran it, its share of all adds' seconds and its
    seconds over the touch's own search (median over those adds); the first touches are not adds."""
    from tactrec.bench.multi_touch_report import summary

    def step(seconds, own, context=0.0):
        return {"best": "a", "correct": True, "confidence": 1.0, "seconds": seconds, "own_seconds": own,
                "slipped": [], "stages": {"own": own, "joint": 0.5, "context": context}}

    first = step(100.0, 99.0)
    rows = [{"random": [first, step(2.0, 1.0), step(4.0, 1.0, context=2.0)],
             "next": [first, step(10.0, 1.0, context=5.0), step(3.0, 2.0)]}]
    parts = summary(rows, STRATEGIES, 5)["random"]["add_stages"]
    assert [parts[k]["adds"] for k in STAGES] == [2, 2, 1]
    assert parts["own"]["share"] == pytest.approx(2.0 / 6.0) and parts["context"]["share"] == pytest.approx(2.0 / 6.0)
    assert parts["own"]["over_own_median"] == pytest.approx(1.0) and parts["context"]["over_own_median"] == 2.0
    other = summary(rows, STRATEGIES, 5)["next"]["add_stages"]
    assert other["context"]["adds"] == 1 and other["context"]["over_own_median"] == pytest.approx(5.0)
    assert other["own"]["share"] == pytest.approx(3.0 / 13.0)


@pytest.mark.parametrize("noise", [0.03, 0.0])
def test_multi_touch_tells_a_found_true_pose_from_a_missed_one(small, noise):
    """The bench's check of the true pose: a session that found it (seeded touches of a small mesh,
    noisy or noise-free, where the true pose fits to rounding) passes under the true world pose,
    and fails once its pose of the true model fits the touches worse by their noise allowance
    (a miss of the searches), or when it has no pose of it."""
    import dataclasses

    from tactrec.bench.multi_touch import truth_of
    from tactrec.bench.multi_touch_report import summary, truth_found

    entry = small[0]
    Rw, tw = random_rigid_motion(np.random.default_rng((11, 0)), extent=300.0)
    world2model = (Rw.T, -Rw.T @ tw, 1.0)
    with Recognizer(small) as recognizer:
        session = recognizer.session()
        for i in range(2):
            touch = simulate_random_touch(entry.model, rng=np.random.default_rng((12, i)), **dict(NOISY, noise=noise))
            session.add(touch, sensor_to_world(touch, (Rw, tw)))
    assert session.result.best == entry.name
    truth = truth_of(session, entry, world2model)
    assert truth["points"] == sum(len(f.points) for f in session.features)
    assert truth_found(truth)
    worse = max(truth["fit"], truth["limit"]) + 0.02
    h = session.result.hypothesis(entry.name)
    missed = dataclasses.replace(h, per_touch=np.full_like(np.asarray(h.per_touch), worse))
    session.result = dataclasses.replace(session.result, ranking=[missed if r is h else r
                                                                  for r in session.result.ranking])
    assert not truth_found(truth_of(session, entry, world2model))
    session.result = dataclasses.replace(session.result, ranking=[r for r in session.result.ranking if r is not missed])
    gone = truth_of(session, entry, world2model)
    assert gone["found"] is None and not truth_found(gone)
    step = {"best": "a", "correct": True, "confidence": 1.0, "seconds": 1.0, "own_seconds": 1.0, "slipped": []}
    found, lost = dict(truth), dict(truth, found=worse)
    rows = [{s: [dict(step, truth=found), dict(step, truth=t)] for s in STRATEGIES} for t in (found, lost)]
    per_k = summary(rows, STRATEGIES, 5)["next"]["per_touches"]
    assert [p["truth_found_percent"] for p in per_k[:2]] == [100.0, 50.0]


def test_a_random_next_touch_is_found_within_reach_on_a_large_object():
    """The bench's random next touch on the pitcher base, where as few as 3% of the faces lie within
    40 mm of a contact, from the face of 40 drawn with the fewest faces within that reach: on 20
    seeded draws a touch is found every time, and within reach of the earlier contact."""
    from types import SimpleNamespace

    from tactrec.bench.multi_touch import RADIUS, SPECS, next_touch
    from tactrec.surfaces import load_model

    model = load_model("pitcher_base")
    centres = np.asarray(model.vertices)[np.asarray(model.faces)].mean(axis=1)
    rng = np.random.default_rng(3)

    def share(c):
        return np.mean(np.linalg.norm(centres - c, axis=1) <= RADIUS)

    start = min(centres[rng.integers(len(centres), size=40)], key=share)
    assert share(start) < 0.05, "the start is not a sparse one: the check below is weak"
    session = SimpleNamespace(contacts=lambda: np.array([start]), recognizer=SimpleNamespace(estimation={}))
    truth = (np.eye(3), np.zeros(3), 1.0)
    for seed in range(20):
        found = next_touch("random", session, SimpleNamespace(model=model), truth, SPECS["hard-10"],
                            np.random.default_rng(seed))
        assert found is not None
        data, (R, t) = found
        world = np.concatenate(data.curves) @ R.T + t                   # the touch's points in the world
        assert np.min(np.linalg.norm(world - start, axis=1)) <= RADIUS + 1e-6     # rounding aside


def test_the_bench_asks_next_again_when_its_touch_cannot_be_made(small):
    """The bench's next touch for ``next``: a proposed line whose touch the simulation refuses (the
    curves along one direction) is asked for again, as a robot whose touch failed would; the touch
    made is where the second line meets the object; a line that meets nothing comes back as the
    missed line; a proposal of nothing ends the session."""
    from types import SimpleNamespace

    from tactrec.bench.multi_touch import SPECS, next_touch
    from tactrec.io.session import MissedLine

    model = small[0].model
    frames = [model.site_frame(s) for s in model.random_sites(2, rng=np.random.default_rng(5))]

    def towards(frame, directions):
        line = MissedLine(frame.point + 10.0 * frame.normal, -frame.normal, 20.0)
        return SimpleNamespace(contact=frame.point, directions=directions, approach=line)

    bad = towards(frames[0], np.stack([frames[0].d1, frames[0].d1]))
    good = towards(frames[1], np.stack([frames[1].d1, frames[1].d2]))
    asked = []

    def propose(proposals):
        def next_(**_):
            asked.append(1)
            return proposals[min(len(asked), len(proposals)) - 1]
        return next_

    session = SimpleNamespace(contacts=lambda: np.array([frames[0].point]), recognizer=SimpleNamespace(estimation={}),
                              next=propose([bad, good]))
    truth = (np.eye(3), np.zeros(3), 1.0)
    spec = dict(SPECS["hard-10"], noise=0.0)
    data, (R, t) = next_touch("next", session, small[0], truth, spec, np.random.default_rng(0))
    assert len(asked) == 2
    world = np.concatenate(data.curves) @ R.T + t
    assert np.min(np.linalg.norm(world - frames[1].point, axis=1)) < 0.3       # the curves meet there
    asked.clear()
    away = MissedLine(frames[1].point + 10.0 * frames[1].normal, frames[1].normal, 20.0)
    session.next = propose([SimpleNamespace(contact=frames[1].point, directions=good.directions, approach=away)])
    assert next_touch("next", session, small[0], truth, spec, np.random.default_rng(0)) is away
    asked.clear()
    session.next = propose([SimpleNamespace(contact=None, directions=None)])
    assert next_touch("next", session, small[0], truth, spec, np.random.default_rng(0)) is None and len(asked) == 1


def test_the_search_budget_bounds_step_5_and_none_lifts_it(scans):
    """Three hard touches of the mug and of the pear, each in one world pose, on four scans
    searched under a small budget, in sessions of three budgets for step 5: with none
    (``search_budget=0``) no add searches beyond the touch's own; with the default, the searches of
    each of step 5's two passes (the best pose's, then its rivals') share what the touch's own
    search spent (each starts only while some is left, and may spend what is left); without a
    budget (None) some add's search may spend more.  A negative budget is refused."""
    spent = {0.0: [], 1.0: [], None: []}
    with Recognizer(scans.entries, budget=20_000) as recognizer:
        for k, j in ((1, 2), (2, 1)):
            pose = random_rigid_motion(np.random.default_rng((30, k, j)), extent=300.0)
            for budget in spent:
                session = recognizer.session(search_budget=budget)
                for i in range(3):
                    rng = np.random.default_rng((32, k, j, i))
                    touch = simulate_random_touch(scans.entries[k].model, rng=rng, **HARD)
                    result = session.add(touch, sensor_to_world(touch, pose))
                    spent[budget].append(([(allowed, work) for work, allowed in result.searched[1:]],
                                          session.records[-1].own.work))
        with pytest.raises(ValueError):
            recognizer.session(search_budget=-1.0)
    assert all(not searches for searches, _ in spent[0.0])
    for searches, own in spent[1.0]:
        before, passes = 0, 1
        for allowed, work in searches:
            if allowed > own - before:               # the rivals' pass starts with the whole budget again
                before, passes = 0, passes + 1
            assert before < own and allowed <= own - before, (searches, own)
            before += work
        assert passes <= 2, (searches, own)
    assert any(searches for searches, _ in spent[1.0]), "no add searched again: the budget went unchecked"
    assert any(a > own for searches, own in spent[None] for a, _ in searches), \
        "no add's search could spend beyond its own search's work without a budget: the option went unchecked"


def _bumped_boxes():
    """A box (80 x 60 x 40 mm) and the same box with one bump on its top face (3 mm high, 8 mm in
    radius, at x = 20, y = 10): two models that every touch away from the bump fits alike."""
    import trimesh

    from tactrec.database import ModelEntry
    from tactrec.surfaces.mesh import MeshModel
    from tactrec.tables import CurvatureTable

    box = trimesh.creation.box(extents=(80.0, 60.0, 40.0))
    for _ in range(5):
        box = box.subdivide()
    v = box.vertices.copy()
    r = np.hypot(v[:, 0] - 20.0, v[:, 1] - 10.0)
    top = (v[:, 2] > 19.999) & (r < 8.0)
    v[top, 2] += 3.0 * np.cos(0.5 * np.pi * r[top] / 8.0) ** 2
    out = []
    for name, vertices in (("box", box.vertices), ("bumped", v)):
        model = MeshModel(vertices, box.faces, name=name, units="mm")
        out.append(ModelEntry(model, CurvatureTable(model.table_samples())))
    return out


def test_next_takes_its_candidates_where_near_duplicates_differ():
    """The disagreement map (tactrec.proposal.disagreement) on a box and its copy with one bump, at
    the same pose, after touches at a corner of the top face: over the whole box the places that
    disagree most all lie on the bump, the only place where the two surfaces differ, and by far more
    than the noise; within a reach that leaves the bump out, nothing disagrees.  A box drawn at
    2,000 random vertices, a bump over about a hundredth of its surface."""
    from tactrec.proposal.disagreement import places
    from tactrec.proposal.gain import information
    from tactrec.session import Hypothesis

    entries = _bumped_boxes()
    models = {e.name: e.model for e in entries}
    bump = np.array([20.0, 10.0])
    g = np.linspace(-6.0, 6.0, 13)
    touched = np.array([[x, y, 20.0] for x in -34.0 + g for y in -24.0 + g])
    pose = np.concatenate([np.eye(3), np.zeros((3, 1))], axis=1)
    H0 = information(models["box"], pose, 1.0, touched)
    box, bumped = (Hypothesis(name, np.eye(3), np.zeros(3), 1.0, 0.0, np.zeros(1), (True,)) for name in models)
    for k in range(4):
        for h, rival in ((box, bumped), (bumped, box)):
            found = places(models, h, pose, H0, [(rival, pose, H0)], touched[84:85], np.array([0.0, 0.0, 1.0]),
                           radius=None, sigma=0.05, rng=k)[:5]
            assert len(found) == 5
            for place in found:
                assert np.linalg.norm(place.point[:2] - bump) < 8.0 and place.disagreement > 3.0
            near = places(models, h, pose, H0, [(rival, pose, H0)], touched[84:85], np.array([0.0, 0.0, 1.0]),
                          radius=20.0, sigma=0.05, rng=k)
            assert len(near) >= 5 and max(p.disagreement for p in near) < 1e-6


def test_next_aims_where_near_duplicates_differ():
    """Twenty seeded one-touch sessions on the plain box of a box and its copy with one bump, the
    touch at a corner of the top face away from the bump (both fit it alike).  A box's corners are
    all alike within a touch's reach, so the bumped box's pose found puts the bump anywhere, often
    on a face turned away from the touch, out of reach: at least four of the twenty put it within
    reach.  Where the bump can be reached,
    ``next`` aims at it, the only place where the two surfaces differ: the line meets the bumped
    box's top face close enough to the bump for the touch's curves (12 mm each way) to cross it,
    within 20 mm of its centre, a fifteenth of the box's surface."""
    from tactrec.simulation import simulate_world_touch

    entries = _bumped_boxes()
    bump = np.array([20.0, 10.0, 20.0])
    aimed = 0
    with Recognizer(entries) as recognizer:
        for k in range(20):
            rng = np.random.default_rng((31, k))
            Rw, tw = random_rigid_motion(rng, extent=300.0)
            world2model = (Rw.T, -Rw.T @ tw, 1.0)
            spot = np.array([rng.uniform(-37.0, -34.0), rng.uniform(-27.0, -24.0), 20.0])     # away from the bump
            a = rng.uniform(0.0, np.pi)
            directions = np.array([[np.cos(a), np.sin(a), 0.0], [np.cos(a + 1.0), np.sin(a + 1.0), 0.0]]) @ Rw.T
            touch, pose = simulate_world_touch(entries[0].model, world2model, spot @ Rw.T + tw, directions,
                                               points=81, spacing=0.3, noise=0.0, outward=True, rng=rng)
            session = recognizer.session()
            result = session.add(touch, pose)
            assert {h.model for h in leading_hypotheses(result)} == {"box", "bumped"}
            proposal = session.next(radius=80.0, rng=k)
            assert proposal.contact is not None
            h = result.hypothesis("bumped")
            if (h.rotation.T @ [0.0, 0.0, 1.0]) @ session.features[0].geometry.normal < 0.0:
                continue                  # the pose found puts the bump on the far side, out of reach
            aimed += 1
            line = proposal.approach
            # where the line meets the bumped box's surface under its pose, in its frame
            x = h.scale * (line.start + np.linspace(0.0, line.length, 2001)[:, None] * line.direction) @ h.rotation.T \
                + h.translation
            inside = np.nonzero(entries[1].model.planes(x)[0] <= 0.0)[0]
            assert len(inside), k
            assert np.linalg.norm(x[inside[0], :2] - bump[:2]) <= 8.0 + 12.0 and x[inside[0], 2] > 19.0, k
    assert aimed >= 4


def test_next_locates_the_object_again_when_a_line_met_nothing_where_every_pose_put_it(small):
    """Four seeded one-touch sessions of the egg: a line reported to have met nothing though it runs
    through the touch's contact cuts into every pose that fits the touch, so no leading pose fits
    the evidence; ``next`` then sends its line through a touched point, where the data say the
    object is, rather than where those poses predict it."""
    from tactrec.io.session import MissedLine
    from tactrec.proposal import pose_fits

    egg = small[0]
    with Recognizer(small) as recognizer:
        for k in range(4):
            Rw, tw = random_rigid_motion(np.random.default_rng((16, k)), extent=300.0)
            touch = simulate_random_touch(egg.model, rng=np.random.default_rng((17, k)), **dict(NOISY, points=31))
            session = recognizer.session()
            session.add(touch, sensor_to_world(touch, (Rw, tw)))
            c, n = session.contacts()[0], session.features[0].geometry.normal
            session.add_miss(MissedLine(c + 10.0 * n, -n, 20.0))
            assert not any(pose_fits(session, h) for h in leading_hypotheses(session.result))
            proposal = session.next(radius=20.0, rng=k)
            x = session.features[0].points
            assert np.min(np.linalg.norm(x - proposal.contact, axis=1)) < 1e-9, k


def test_a_touch_the_truth_meets_is_worth_more_than_a_line_it_misses():
    """The expected gain weighs ``unknown`` too (tactrec.proposal): two models and unknown, and lines
    that tell the models apart completely, one that the true model's pose meets (a touch it fits,
    which leaves unknown less likely) and one that it misses (no fit to weigh): the first gains more,
    whether unknown holds 0.2 or 0.9 of the probability.  No line gains less than nothing, and one
    that the truth misses and that tells the models nothing gains nothing."""
    from tactrec.proposal.gain import expected_gain

    apart, alike = np.array([[0.0, 50.0], [50.0, 0.0]]), np.zeros((2, 2))    # truth pose (rows), model fitted
    takes, hit, miss = np.ones(2, dtype=bool), np.ones(2, dtype=bool), np.zeros(2, dtype=bool)
    for u in (0.2, 0.9):
        w = np.full(2, (1.0 - u) / 2)
        gains = {(z_name, h_name): expected_gain(w, u, z, h, w, takes)
                 for z_name, z in (("apart", apart), ("alike", alike)) for h_name, h in (("hit", hit), ("miss", miss))}
        assert gains["apart", "hit"] > gains["apart", "miss"] > 0.0
        assert gains["alike", "hit"] > 0.0 and gains["alike", "miss"] == pytest.approx(0.0, abs=1e-12)


def test_the_near_duplicates_set_differs_only_at_its_bump_and_starts_clear_of_it(small):
    """``bench multi-touch``'s near-duplicates (tactrec.bench.near_duplicates), on the egg: the copy
    differs from the original only within half the bump's width of its centre, by its height there
    and never more; the truth alternates between the two; every point of the first touch lies at
    least NEAR less the curves' 6 mm from the bump's centre, clear of the bump (5 mm in radius)."""
    from tactrec.bench import near_duplicates as nd

    cache = {}
    entries, centre = nd.family(small[0], 0, 0, cache)
    v0, v1 = entries[0].model.vertices, entries[1].model.vertices
    moved = np.linalg.norm(v1 - v0, axis=1)
    r = np.linalg.norm(v0 - v0[centre], axis=1)
    assert np.all(moved[r >= 0.5 * nd.WIDTH] == 0.0) and moved.max() <= nd.HEIGHT + 1e-9
    assert moved[centre] == pytest.approx(nd.HEIGHT) and np.count_nonzero(moved) >= nd.BUMP_VERTICES
    spec = {"length": 12.0, "angle": 30.0, "noise": 0.05, "outward": False}
    for i in range(4):
        truth, data = nd.first_touch(entries, centre, 0, i, 0, spec, 0.3)
        assert truth is entries[i % 2]
        truth_pose = data.meta["truth"]
        points = data.points @ np.asarray(truth_pose["rotation"]).T + np.asarray(truth_pose["translation"])
        gap = np.linalg.norm(points - v0[centre], axis=1)
        assert gap.min() >= nd.NEAR - 6.0 - 0.5 > 0.5 * nd.WIDTH


def test_sessions_that_never_touch_where_near_duplicates_differ_are_never_sure_of_either():
    """Twenty seeded sessions of three noisy touches (12 mm curves, noise 0.05 mm) on the top face of a
    box or of its copy with one bump (alternately), every touch clear of the bump: no touch tells the
    two apart, so no session is ever sure (>= 0.95) of either, and the other's joint pose fits every
    touch as the truth's does (a joint pose the search missed is searched again, never read as
    evidence against its model)."""
    from tactrec.simulation import simulate_world_touch

    entries = _bumped_boxes()
    bump = np.array([20.0, 10.0])
    with Recognizer(entries, workers=2) as recognizer:
        for k in range(20):
            rng = np.random.default_rng((47, k))
            truth, twin = ("box", "bumped") if k % 2 == 0 else ("bumped", "box")
            model = entries[0 if truth == "box" else 1].model
            Rw, tw = random_rigid_motion(rng, extent=300.0)
            world2model = (Rw.T, -Rw.T @ tw, 1.0)
            session = recognizer.session()
            for _ in range(3):
                while True:
                    spot = np.array([rng.uniform(-26.0, 26.0), rng.uniform(-16.0, 16.0), 20.0])
                    if np.linalg.norm(spot[:2] - bump) > 8.0 + 14.0:
                        break
                a = rng.uniform(0.0, np.pi)
                directions = np.array([[np.cos(a), np.sin(a), 0.0], [np.cos(a + 0.52), np.sin(a + 0.52), 0.0]]) @ Rw.T
                touch, pose = simulate_world_touch(model, world2model, spot @ Rw.T + tw, directions, points=41,
                                                   spacing=0.3, noise=0.05, noise_kind="gaussian", outward=False,
                                                   rng=rng)
                result = session.add(touch, pose)
                assert result.confidence < 0.95, (k, truth, result.best, result.probabilities)
            h = result.hypothesis(twin)
            assert h is not None and all(h.consistent), (k, truth, twin)


def test_a_later_touch_searches_the_standing_models_first_and_every_model_where_none_fits(small):
    """A session on a catalogue: once its touches leave standing hypotheses (models whose joint pose
    is consistent with every touch), a new touch is searched among their models only where one of
    them fits it, and over every model where none does.  20 seeded sessions of two noisy touches
    of the four meshes: wherever touch 1 left standing fewer models than all and touch 2 fits one, the
    others were not searched for touch 2 (a standing model the index reads far from the fit need not
    be either), and the sessions are right and sure on at least 19.  Then
    a touch of the ring after two of the egg: no standing pose fits it, so its own search goes past
    the standing models and poses the ring."""
    right, narrowed = 0, 0
    with Recognizer(small) as recognizer:
        for k in range(20):
            entry = small[k % len(small)]
            pose = random_rigid_motion(np.random.default_rng((40, k)), extent=300.0)
            session = recognizer.session()
            _add_touches(session, entry.model, pose, 1, 41 + 1000 * k)
            standing = {h.model for h in session.result.ranking if all(h.consistent)}
            _add_touches(session, entry.model, pose, 1, 42 + 1000 * k)
            result, own = session.result, session.records[-1].own
            right += result.best == entry.name and result.confidence >= 0.95
            searched = {r.model for r in own.ranking if r.outcome is not Outcome.NOT_SEARCHED}
            if standing and len(standing) < len(small) and any(r.ok and r.model in standing for r in own.ranking):
                narrowed += 1
                assert searched <= standing, (k, searched, standing)
        assert right >= 19, right
        assert narrowed >= 10, f"only {narrowed} sessions searched their standing models first: the check is vacuous"
        egg, ring = small[0], small[3]
        pose = random_rigid_motion(np.random.default_rng((43,)), extent=300.0)
        session = recognizer.session()
        _add_touches(session, egg.model, pose, 2, 44)
        assert {h.model for h in session.result.ranking if all(h.consistent)} == {egg.name}
        touch = simulate_random_touch(ring.model, rng=np.random.default_rng((45,)), **NOISY)
        session.add(touch, sensor_to_world(touch, pose))
        own = session.records[-1].own
        assert own.best == ring.name                 # not among the standing models: the search went past them
