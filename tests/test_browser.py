"""The viewer's page in a real browser: headless Chromium (Debian's ``chromium``, which ``make test``
installs), driven by Playwright with that executable (no downloaded browser build).

The page must draw its model with no console error and no request beyond its own file; the side
panel must list the result's models (and a session's touches).  A still (``--png``) must show the
model and its red curves.  The same checks are run on a broken copy of the page, so that
a blank, erring or fetching page is seen to fail them."""

import json
import re
import shutil

import numpy as np
import pytest

from tactrec.recognition import Recognizer
from tactrec.simulation import simulate_touch
from tactrec.viewer import render_still, still, touch_scene, write_view

WIDTH, HEIGHT, SIDE = 1200, 800, 340          # the window, and the side panel's width (page.py)


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for the module's pages (each page opens in its own context)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        assert shutil.which("chromium"), "chromium not found: 'make test' installs Debian's chromium package"
        chromium = still.launch(p)
        try:
            yield chromium
        finally:
            chromium.close()


def visit(browser, path) -> dict:
    """Open ``path`` in a fresh context of ``browser``; what happened: console errors, requests beyond
    the file, whether it drew, the side panel's models, and the plot's screenshot as an ``(h, w, 3)``
    array."""
    from io import BytesIO

    from matplotlib.image import imread

    report = {"errors": [], "requests": []}
    url = path.resolve().as_uri()
    context = browser.new_context(viewport={"width": WIDTH, "height": HEIGHT})
    try:
        page = context.new_page()
        page.on("console", lambda m: report["errors"].append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: report["errors"].append(str(e)))
        page.on("request", lambda r: report["requests"].append(r.url) if r.url != url else None)
        page.goto(url)
        try:
            page.wait_for_selector("body[data-drawn]", timeout=30000)
            report["drawn"] = True
        except Exception:
            report["drawn"] = False
        page.wait_for_timeout(300)
        report["models"] = page.eval_on_selector_all("#models li", "els => els.map(e => e.dataset.model)")
        report["legend"] = page.eval_on_selector_all("#legend li", "els => els.map(e => e.textContent)")
        report["pixels"] = imread(BytesIO(page.screenshot()), format="png")[:, SIDE:, :3]
    finally:
        context.close()
    return report


def model_share(pixels: np.ndarray) -> float:
    """The share of the plot's pixels that are the model's grey shading (neither the white
    background nor the axes' light lines, nor a coloured curve)."""
    grey = (np.ptp(pixels, axis=2) < 0.04) & (pixels.mean(axis=2) > 0.15) & (pixels.mean(axis=2) < 0.85)
    return float(grey.mean())


@pytest.fixture(scope="module")
def page_of_a_result(scans, tmp_path_factory):
    rng = np.random.default_rng(2)
    mug = next(e.model for e in scans.entries if e.name == "mug")
    touch = simulate_touch(mug, [int(rng.integers(len(mug.vertices)))], points=61, spacing=0.3, angle=60.0, rng=rng)
    with Recognizer(scans) as recognizer:
        result = recognizer.recognize(touch).to_json()
    path = tmp_path_factory.mktemp("viewer") / "view.html"
    write_view(path, touch_scene(result, touch.curves, {e.name: e.model for e in scans.entries}, title="mug"))
    return path, result


def test_the_page_draws_its_model_offline_without_errors(browser, page_of_a_result):
    path, result = page_of_a_result
    report = visit(browser, path)
    assert report["errors"] == [] and report["requests"] == []
    assert report["drawn"]
    assert report["models"] == [r["model"] for r in result["ranking"]]
    # the model covers a plausible share (all of it, seen from inside a cup), and the curves show
    assert 0.05 < model_share(report["pixels"]) < 0.99 and colour_share(report["pixels"]) > 1e-3


def test_a_blank_erring_or_fetching_page_fails_the_checks(browser, page_of_a_result, tmp_path):
    path, _ = page_of_a_result
    text = path.read_text(encoding="utf-8")
    fetching = tmp_path / "fetching.html"
    fetching.write_text(text.replace("</body>", "<img src=\"http://example.invalid/x.png\"></body>"), encoding="utf-8")
    erring = tmp_path / "erring.html"
    erring.write_text(text.replace("const scene = JSON.parse", "console.error('broken'); const scene = JSON.parse"),
                      encoding="utf-8")
    blank = tmp_path / "blank.html"
    blank.write_text(text.replace("show(0); }", "document.body.dataset.drawn = 'yes'; }"), encoding="utf-8")
    assert any("example.invalid" in url for url in visit(browser, fetching)["requests"])
    assert "broken" in visit(browser, erring)["errors"]
    assert model_share(visit(browser, blank)["pixels"]) < 0.01


def colour_share(pixels: np.ndarray) -> float:
    """The share of pixels of a saturated colour (the curves')."""
    return float((np.ptp(pixels, axis=2) > 0.3).mean())


def red_share(pixels: np.ndarray) -> float:
    """The share of pixels that are a curve's red (Fig. 14's colour, shaded)."""
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    return float(((r > 0.45) & (g < 0.3) & (b < 0.3) & (r > 2.0 * g)).mean())


def test_a_still_shows_the_model_and_its_curves_at_print_size(browser, page_of_a_result, tmp_path):
    """The still of the mug's touch: 1600 x 1200 pixels, the model a plausible share of them, the red
    curves at least 0.1 % (visible at print size); without the curves, none red."""
    from matplotlib.image import imread

    from tactrec.viewer.page import page as page_text

    path, result = page_of_a_result
    text = path.read_text(encoding="utf-8")
    png = tmp_path / "still.png"
    render_still(text, png, browser=browser)
    pixels = imread(png)[..., :3]
    assert pixels.shape[:2] == (1200, 1600)
    assert 0.05 < model_share(pixels) < 0.99
    assert red_share(pixels) > 1e-3
    bare = json.loads(re.search(r'id="scene">(.*?)</script>', text, re.S).group(1))
    for view in bare["views"]:
        view["curves"] = []
    render_still(page_text(bare), png, browser=browser)
    assert red_share(imread(png)[..., :3]) < 1e-4


def test_a_sessions_page_draws_and_lists_its_touches(browser, tmp_path):
    """A session of two touches of the elliptic cylinder: drawn offline without errors, its models and
    touches listed."""
    from tactrec.io.session import SessionTouch
    from tactrec.simulation import random_rigid_motion, sensor_to_world, simulate_random_touch
    from tactrec.surfaces import load_model
    from tactrec.viewer import session_scene

    names = ["elliptic-cylinder", "cylinder-50", "sphere-33"]
    models = {n: load_model(n) for n in names}
    from tactrec.database import open_models

    db = open_models(models=names)
    pose = random_rigid_motion(np.random.default_rng((3,)), extent=100.0)
    items = []
    with Recognizer(db) as recognizer:
        session = recognizer.session()
        for i in range(2):
            touch = simulate_random_touch(models["elliptic-cylinder"], rng=np.random.default_rng((4, i)),
                                          points=21, spacing=0.5,
                                          angle=60.0, noise=0.01, noise_kind="gaussian", outward=False)
            items.append(SessionTouch(touch, *sensor_to_world(touch, pose)))
            session.add(touch, (items[-1].rotation, items[-1].translation))
        result = session.result.to_json()
    path = tmp_path / "session.html"
    write_view(path, session_scene(result, items, models, title="session"))
    report = visit(browser, path)
    assert report["errors"] == [] and report["requests"] == [] and report["drawn"]
    assert report["models"] == [r["model"] for r in result["ranking"]]
    assert report["legend"][:2] == ["touch 1", "touch 2"]
    assert 0.05 < model_share(report["pixels"]) < 0.9
