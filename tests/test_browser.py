"""The viewer's page in a real browser: headless Chromium (Debian's ``chromium``, which ``make test``
installs), driven by Playwright with that executable (no downloaded browser build).

The page must draw its model with no console error and no request beyond its own file; the side
panel must list the result's models.  The same checks are run on a broken copy of the page, so that
a blank, erring or fetching page is seen to fail them."""

import shutil

import numpy as np
import pytest

from tactrec.recognition import Recognizer
from tactrec.simulation import simulate_touch
from tactrec.viewer import touch_scene, write_view

WIDTH, HEIGHT, SIDE = 1200, 800, 340          # the window, and the side panel's width (page.py)


def _chromium() -> str:
    path = shutil.which("chromium")
    assert path, "chromium not found: 'make test' installs Debian's chromium package"
    return path


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for the module's pages (each page opens in its own context)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=_chromium(),
                                     args=["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"])
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
    assert 0.05 < model_share(report["pixels"]) < 0.9


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
