"""The offline viewer: tubes, scenes placed by each model's pose, and ``tactrec show``'s page."""

import json
import re

import numpy as np
import pytest

from tactrec.cli import main
from tactrec.recognition import Recognizer
from tactrec.simulation import simulate_touch
from tactrec.viewer.scene import SIDES, surface_mesh, touch_scene, tube


def test_a_tube_rings_each_point_of_its_curve_at_its_radius():
    """Every ring lies across the curve at its point, ``radius`` from it; the rings are stitched into
    ``2 (n - 1) SIDES`` triangles, none degenerate, over a helix (a curve that turns and twists)."""
    s = np.linspace(0.0, 4.0 * np.pi, 60)
    curve = np.stack([np.cos(s), np.sin(s), 0.3 * s], axis=1)
    vertices, triangles = tube(curve, 0.05)
    assert vertices.shape == (60 * SIDES, 3) and triangles.shape == (2 * 59 * SIDES, 3)
    rings = vertices.reshape(60, SIDES, 3) - curve[:, None]
    assert np.allclose(np.linalg.norm(rings, axis=2), 0.05)
    tangent = np.gradient(curve, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    assert np.max(np.abs(np.einsum("nsk,nk->ns", rings, tangent))) < 1e-9
    corners = vertices[triangles]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    assert area.min() > 0.0


def test_a_large_mesh_is_decimated_for_display_and_says_from_how_many(scans):
    mug = next(e.model for e in scans.entries if e.name == "mug")
    vertices, triangles, original = surface_mesh(mug, faces=2000)
    assert original == len(mug.faces) > 2000
    assert 1800 <= len(triangles) <= 2000 and triangles.max() < len(vertices)
    # the drawn surface stays on the scan: its vertices within a small share of its size
    assert np.percentile(mug.distance(vertices), 95) < 0.01 * mug.size


def test_each_view_places_the_curves_by_its_own_models_pose(scans):
    """Over 20 seeded touches, each view's curves (the tubes' ring centres) lie on that view's model
    as its registration fits them: their mean distance is the registration's error; the first view
    is the best model's, and the right one in 19 or more."""
    models = {e.name: e.model for e in scans.entries}
    rng = np.random.default_rng(5)
    right = 0
    with Recognizer(scans) as recognizer:
        for k in range(20):
            entry = scans.entries[k % len(scans.entries)]
            touch = simulate_touch(entry.model, [int(rng.integers(len(entry.model.vertices)))], points=41,
                                   spacing=0.3, angle=60.0, rng=rng)
            result = recognizer.recognize(touch).to_json()
            scene = touch_scene(result, touch.curves, models, shown=3, faces=3000, runner_faces=1000)
            registered = [r for r in result["ranking"] if r.get("error") is not None][:3]
            assert [v["model"] for v in scene["views"]] == [r["model"] for r in registered]
            right += scene["views"][0]["model"] == entry.name
            for view, r in zip(scene["views"], registered):
                centres = [np.asarray(c["vertices"]).reshape(-1, SIDES, 3).mean(axis=1) for c in view["curves"]]
                distance = models[view["model"]].distance(np.concatenate(centres))
                assert abs(distance.mean() - r["error"]) <= 0.02 * r["error"] + 1e-3 * models[view["model"]].size
                assert np.allclose(view["contact"], r["location"], atol=1e-3 * view["size"])
    assert right >= 19


@pytest.mark.slow
def test_show_writes_one_offline_page_of_the_result(tmp_path, capsys):
    """``tactrec show`` on a touch against six YCB scans (a database built once): one page under
    8 MB, three.js inlined with its licence (no script, stylesheet or image fetched from anywhere), the
    scene listing the ranking's models; ``--result`` draws a saved result without recognising again."""
    touch = tmp_path / "touch.json"
    assert main(["simulate", "mug", "--out", str(touch), "--vertex", "700", "--seed", "3", "--quiet"]) == 0
    models = ["apple", "banana", "hammer", "mug", "pear", "strawberry"]
    db = tmp_path / "db"
    assert main(["build", *models, "--out", str(db), "--quiet"]) == 0
    out = tmp_path / "view.html"
    assert main(["show", str(touch), "--db", str(db), "--out", str(out), "--quiet"]) == 0
    text = out.read_text(encoding="utf-8")
    assert out.stat().st_size <= 8e6
    assert "three.js authors" in text and "Permission is hereby granted" in text
    assert not re.search(r"<(script|link|img|iframe)[^>]+(src|href)\s*=", text)
    scene = _scene_of(out)
    assert scene["best"] == "mug" and scene["views"][0]["model"] == "mug"
    # the side panel lists every model: a view for each registered one (up to 5), why not for the rest
    assert sorted([v["model"] for v in scene["views"]] + [o["model"] for o in scene["others"]]) == models
    assert all(o["reason"] for o in scene["others"])
    assert scene["views"][0]["surface"]["faces"] <= 10000
    capsys.readouterr()
    assert main(["recognize", str(touch), "--db", str(db), "--json"]) == 0
    saved = tmp_path / "result.json"
    saved.write_text(capsys.readouterr().out, encoding="utf-8")
    again = tmp_path / "again.html"
    assert main(["show", str(touch), "--db", str(db), "--result", str(saved), "--out", str(again), "--quiet"]) == 0
    assert _scene_of(again) == scene


def test_show_refuses_a_result_it_cannot_draw_in_one_line(tmp_path, capsys):
    touch = tmp_path / "touch.json"
    assert main(["simulate", "sphere-33", "--out", str(touch), "--uv", "0.5,0.5", "--seed", "1", "--quiet"]) == 0
    out = tmp_path / "view.html"
    cases = {"empty.json": ("", "empty file"),
             "list.json": ("[1, 2]", "each line must be a JSON object"),
             "noranking.json": ('{"best": "x"}', "no 'ranking'"),
             "pose.json": ('{"ranking": [{"model": "sphere-33", "error": 0.1, "rotation": [[2, 0, 0], [0, 1, 0], '
                           '[0, 0, 1]], "translation": [0, 0, 0], "location": [0, 0, 0]}]}', "rotation"),
             "other.json": ('{"ranking": [{"model": "torus-x", "error": 0.1, "rotation": [[1, 0, 0], [0, 1, 0], '
                            '[0, 0, 1]], "translation": [0, 0, 0], "location": [0, 0, 0]}]}', "torus-x"),
             "normal.json": ('{"normal": [0, 0, 0], "ranking": [{"model": "sphere-33", "error": 0.1, "rotation": '
                             '[[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0, 0, 0], "location": [0, 0, 0]}]}',
                             "'normal' has no length"),
             "slipped.json": ('{"slipped": 3, "ranking": [{"model": "sphere-33", "error": null}]}', "'slipped'")}
    for name, (text, words) in cases.items():
        bad = tmp_path / name
        bad.write_text(text, encoding="utf-8")
        capsys.readouterr()
        assert main(["show", str(touch), "--models", "sphere-33", "--result", str(bad), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and name in err and words in err, err
        assert not out.exists()


def test_a_sessions_views_draw_each_touch_where_the_joint_pose_puts_it():
    """Three touches of the egg and a fourth after it moved (slipped), in random sensor frames: the
    egg's view draws every touch, each fitted touch's curves on the egg at its per-touch error, the
    slipped one faded and crossed (and listed so), the axes' range about the egg, not the slipped
    curves."""
    from conftest import small_meshes
    from tactrec.io.session import SessionTouch
    from tactrec.simulation import random_rigid_motion, sensor_to_world, simulate_random_touch
    from tactrec.viewer import session_scene

    small = small_meshes()
    models = {e.name: e.model for e in small}
    noisy = dict(points=41, spacing=0.3, angle=60.0, noise=0.03, noise_kind="gaussian", outward=False)
    poses = [random_rigid_motion(np.random.default_rng((9,)), extent=300.0)] * 3 \
        + [random_rigid_motion(np.random.default_rng((10,)), extent=300.0)]
    items = []
    with Recognizer(small) as recognizer:
        session = recognizer.session()
        for i, pose in enumerate(poses):
            touch = simulate_random_touch(models["egg"], rng=np.random.default_rng((11, i)), **noisy)
            R, t = sensor_to_world(touch, pose)
            items.append(SessionTouch(touch, R, t))
            session.add(touch, (R, t))
        result = session.result.to_json()
        proposal = session.next(radius=20.0, rng=0).to_json()
    assert result["best"] == "egg" and result["slipped"] == [3]
    scene = session_scene(result, items, models, proposal=proposal, shown=2)
    assert [e["name"] for e in scene["legend"][:4]] == ["touch 1", "touch 2", "touch 3", "touch 4 (slipped)"]
    egg = scene["views"][0]
    assert egg["model"] == "egg"
    per_touch = next(r for r in result["ranking"] if r["model"] == "egg")["per_touch_error"]
    for k in range(4):
        tubes = [c for c in egg["curves"] if c["name"].startswith(f"touch {k + 1}")]
        assert len(tubes) == 3 and all(c["opacity"] == (0.35 if k == 3 else 1.0) for c in tubes)
        centres = np.concatenate([np.asarray(c["vertices"]).reshape(-1, SIDES, 3).mean(axis=1) for c in tubes])
        assert abs(models["egg"].distance(centres).mean() - per_touch[k]) <= 0.02 * per_touch[k] + 1e-3 * egg["size"]
    symbols = {m["name"]: m["symbol"] for m in egg["marks"]}
    assert symbols["touch 4 (slipped)"] == "x" and symbols["touch 1"] == "circle"
    lo, hi = np.asarray(egg["range"])
    v = models["egg"].vertices
    assert np.all(lo >= v.min(axis=0) - 0.06 * egg["size"]) and np.all(hi <= v.max(axis=0) + 0.06 * egg["size"])
    # the egg holds all but 1e-3 of the probability: nothing to propose, nothing drawn for it
    assert proposal["contact"] is None and len(scene["legend"]) == 4
    assert not any(c["name"].startswith("next") for c in egg["curves"]) and egg["lines"] == []


def test_a_proposed_touch_is_drawn_on_each_hypothesis_that_it_separates():
    """One-touch sessions on the capsule and the ring (round and flat patches alike, so the
    hypotheses stay open): where a touch is proposed, each view draws its approach line, its three
    curves and its contact; on the most probable hypothesis the contact lies on the surface and
    the curves start and end on it."""
    from conftest import small_meshes
    from tactrec.io.session import SessionTouch
    from tactrec.simulation import random_rigid_motion, sensor_to_world, simulate_random_touch
    from tactrec.viewer import session_scene

    small = small_meshes()
    models = {e.name: e.model for e in small}
    noisy = dict(points=21, spacing=0.3, angle=60.0, noise=0.03, noise_kind="gaussian", outward=False)
    proposed = 0
    with Recognizer(small) as recognizer:
        for k in range(6):
            name = ("capsule", "ring")[k % 2]
            touch = simulate_random_touch(models[name], rng=np.random.default_rng((13, k)), **noisy)
            R, t = sensor_to_world(touch, random_rigid_motion(np.random.default_rng((12, k)), extent=300.0))
            session = recognizer.session()
            session.add(touch, (R, t))
            result, proposal = session.result.to_json(), session.next(radius=20.0, rng=k).to_json()
            scene = session_scene(result, [SessionTouch(touch, R, t)], models, proposal=proposal, shown=4)
            if proposal["contact"] is None:
                assert not any(m["name"] == "next: contact" for v in scene["views"] for m in v["marks"])
                continue
            proposed += 1
            assert scene["legend"][-1]["name"].startswith("next touch")
            for v in scene["views"]:
                assert [ln["name"] for ln in v["lines"]] == ["next: approach"]
                assert sum(c["name"].startswith("next: curve") for c in v["curves"]) == 3
            best = scene["views"][[v["model"] for v in scene["views"]].index(proposal["hypotheses"][0]["model"])]
            model = models[best["model"]]
            contact = next(m["point"] for m in best["marks"] if m["name"] == "next: contact")
            assert model.distance(np.asarray([contact]))[0] < 1e-3 * best["size"]
            for c in (c for c in best["curves"] if c["name"].startswith("next: curve")):
                ends = np.asarray(c["vertices"]).reshape(-1, SIDES, 3).mean(axis=1)[[0, -1]]
                assert np.all(model.distance(ends) < 0.01 * best["size"])
    assert proposed >= 3


def _scene_of(path) -> dict:
    text = path.read_text(encoding="utf-8")
    return json.loads(re.search(r'<script type="application/json" id="scene">(.*?)</script>', text,
                                re.S).group(1))


def test_show_draws_a_session_and_its_saved_result_and_proposal_alike(tmp_path, capsys):
    """``tactrec show SESSION``: a session's page (two touches of the elliptic cylinder in their sensors'
    frames); drawn again from ``recognize --json``'s result and ``next --json``'s proposal, the same
    scene; a proposal for a single touch, a malformed proposal and no output are one line each."""
    from tactrec.io.session import SessionTouch, save_session
    from tactrec.simulation import random_rigid_motion, sensor_to_world, simulate_random_touch
    from tactrec.surfaces import load_model

    model = load_model("elliptic-cylinder")
    pose = random_rigid_motion(np.random.default_rng((3,)), extent=100.0)
    items = []
    for i in range(2):
        touch = simulate_random_touch(model, rng=np.random.default_rng((4, i)),
                                      points=21, spacing=0.5, angle=60.0, noise=0.01,
                                      noise_kind="gaussian", outward=False)
        items.append(SessionTouch(touch, *sensor_to_world(touch, pose)))
    session = tmp_path / "session.json"
    save_session(items, session)
    models = ["elliptic-cylinder", "cylinder-50", "cylinder-94", "sphere-33"]
    out = tmp_path / "view.html"
    assert main(["show", str(session), "--models", *models, "--out", str(out), "--quiet"]) == 0
    scene = _scene_of(out)
    assert scene["kind"] == "session" and scene["views"][0]["model"] == scene["best"] == "elliptic-cylinder"
    assert [e["name"] for e in scene["legend"][:2]] == ["touch 1", "touch 2"]
    capsys.readouterr()
    assert main(["recognize", str(session), "--models", *models, "--json"]) == 0
    result = tmp_path / "result.json"
    result.write_text(capsys.readouterr().out, encoding="utf-8")
    assert main(["next", str(session), "--models", *models, "--json"]) == 0
    proposal = tmp_path / "next.json"
    proposal.write_text(capsys.readouterr().out, encoding="utf-8")
    again = tmp_path / "again.html"
    assert main(["show", str(session), "--models", *models, "--result", str(result), "--next", str(proposal),
                 "--out", str(again), "--quiet"]) == 0
    assert _scene_of(again) == scene
    touch = tmp_path / "touch.json"
    touch.write_text(json.dumps(items[0].data.to_json()), encoding="utf-8")
    bad = tmp_path / "bad.json"
    bad.write_text('{"contact": [0, 0, 0], "directions": "north"}', encoding="utf-8")
    flat = tmp_path / "flat.json"
    flat.write_text('{"contact": [0, 0, 0], "directions": [[1, 0, 0], [0, 0, 0]]}', encoding="utf-8")
    cases = [(["show", str(touch), "--next", str(proposal), "--out", str(out)], "next.json"),
             (["show", str(session), "--next", str(bad), "--out", str(tmp_path / "b.html")], "bad.json"),
             (["show", str(session), "--next", str(flat), "--out", str(tmp_path / "b.html")], "no length"),
             (["show", str(session)], "--out")]
    for argv, words in cases:
        capsys.readouterr()
        assert main(argv + ["--models", *models]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err, err
    assert not (tmp_path / "b.html").exists()


def test_the_inlined_library_is_the_published_file_with_its_licence(monkeypatch):
    """The page carries three.js's licence before the library; a vendored file that is not the published
    one (its SHA-256 differs) is refused, not inlined."""
    import importlib

    page_module = importlib.import_module("tactrec.viewer.page")

    text = page_module.library()
    assert text.index("Permission is hereby granted") < text.index("class OrbitControls")
    monkeypatch.setitem(page_module.VENDOR, "three.min.js", "0" * 64)
    with pytest.raises(RuntimeError, match="three.min.js"):
        page_module.library()


def test_a_still_without_a_browser_is_one_line_before_any_work(tmp_path, capsys, monkeypatch):
    """``--png`` where no Chromium is found (``TACTREC_CHROMIUM`` naming none), or what is found is no
    browser: one line, exit status 2, neither the still nor the page written."""
    touch = tmp_path / "touch.json"
    assert main(["simulate", "sphere-33", "--out", str(touch), "--uv", "0.5,0.5", "--seed", "1", "--quiet"]) == 0
    for browser, words in (("no-such-browser", "chromium"), ("true", "did not start as a headless browser")):
        monkeypatch.setenv("TACTREC_CHROMIUM", browser)
        capsys.readouterr()
        assert main(["show", str(touch), "--models", "sphere-33", "--png", str(tmp_path / "s.png"),
                     "--out", str(tmp_path / "v.html")]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--png" in err and words in err, err
        assert not (tmp_path / "s.png").exists() and not (tmp_path / "v.html").exists()


def test_a_sessions_camera_looks_at_a_fitted_touch_from_outside():
    """Two touches of a sphere seen from about 90 degrees apart (the mean of their contacts lies
    inside it): the view looks at the latest touch's contact, on the surface, from outside, with
    the surface leaving the line of sight clear for more than the model's size."""
    from tactrec.io.session import SessionTouch
    from tactrec.simulation import simulate_touch
    from tactrec.surfaces import load_model
    from tactrec.viewer import session_scene

    sphere = load_model("sphere-33")
    touches = [simulate_touch(sphere, uv, points=21, spacing=0.5, angle=60.0, rng=k, sensor_frame=False)
               for k, uv in enumerate(([0.3, 1.0], [0.3, 2.6]))]
    items = [SessionTouch(t) for t in touches]
    eye = np.eye(3).tolist()
    result = {"best": "sphere-33", "confidence": 1.0, "unknown": 0.0, "slipped": [], "normal": [0.0, 0.0, 1.0],
              "ranking": [{"model": "sphere-33", "error": 0.01, "rotation": eye, "translation": [0.0, 0.0, 0.0],
                           "location": [0.0, 0.0, 33.0], "probability": 1.0}]}
    view = session_scene(result, items, {"sphere-33": sphere})["views"][0]
    target = np.asarray(view["target"])
    assert abs(np.linalg.norm(target) - 33.0) < 0.5 and np.allclose(view["contact"], target)
    assert np.linalg.norm(target - sphere.evaluate(0.3, 2.6)) < 0.5                 # the latest touch's
    assert np.asarray(view["look"]) @ target / np.linalg.norm(target) > 0.99
    assert view["clear"] * view["size"] > 66.0
