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
    """``tactrec show`` on a touch against the ten Fig. 11 scans: one page under 8 MB, plotly.js inlined
    (no script, stylesheet or image fetched from anywhere), the scene listing the ranking's models;
    ``--result`` draws a saved result without recognising again."""
    touch = tmp_path / "touch.json"
    assert main(["simulate", "mug", "--out", str(touch), "--vertex", "700", "--seed", "3", "--quiet"]) == 0
    models = ["apple", "banana", "bleach_cleanser", "hammer", "mug", "mustard_bottle", "pear", "pitcher_base",
              "power_drill", "strawberry"]
    out = tmp_path / "view.html"
    assert main(["show", str(touch), "--models", *models, "--out", str(out), "--quiet"]) == 0
    text = out.read_text(encoding="utf-8")
    assert out.stat().st_size <= 8e6
    assert "Licensed under the MIT license" in text and "Plotly" in text
    assert not re.search(r"<(script|link|img|iframe)[^>]+(src|href)\s*=", text)
    scene = json.loads(re.search(r'<script type="application/json" id="scene">(.*?)</script>', text,
                                 re.S).group(1).replace("<\\/", "</"))
    assert scene["best"] == "mug" and scene["views"][0]["model"] == "mug"
    # the side panel lists every model: a view for each registered one (up to 5), why not for the rest
    assert sorted([v["model"] for v in scene["views"]] + [o["model"] for o in scene["others"]]) == models
    assert all(o["reason"] for o in scene["others"])
    assert scene["views"][0]["surface"]["faces"] <= 10000
    capsys.readouterr()
    assert main(["recognize", str(touch), "--models", *models, "--json"]) == 0
    saved = tmp_path / "result.json"
    saved.write_text(capsys.readouterr().out, encoding="utf-8")
    again = tmp_path / "again.html"
    assert main(["show", str(touch), "--models", "mug", "banana", "apple", "pear", "strawberry", "hammer",
                 "bleach_cleanser", "mustard_bottle", "pitcher_base", "power_drill", "--result", str(saved),
                 "--out", str(again), "--quiet"]) == 0
    assert again.exists()


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
                            '[0, 0, 1]], "translation": [0, 0, 0], "location": [0, 0, 0]}]}', "torus-x")}
    for name, (text, words) in cases.items():
        bad = tmp_path / name
        bad.write_text(text, encoding="utf-8")
        capsys.readouterr()
        assert main(["show", str(touch), "--models", "sphere-33", "--result", str(bad), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and name in err and words in err, err
        assert not out.exists()
