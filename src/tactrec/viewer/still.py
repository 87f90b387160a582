"""Stills of the viewer's page (``tactrec show --png``), rendered by a real browser.

The page is opened in headless Chromium (the system's ``chromium``; Debian's package) driven by
Playwright (the ``still`` extra), in its still mode (the page's ``#still``: the plot alone, equal
axes, the best model grey and a touch's curves red with a white contact dot, as in the paper's
Fig. 14), and the browser's own screenshot is written.  Chromium draws WebGL with SwiftShader,
its CPU renderer, so a machine without a GPU or a display makes the same picture.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from ..errors import InputError
from ..io.atomic import write_bytes_atomic

__all__ = ["chromium", "launch", "render_still", "check_still", "ARGS", "WIDTH", "HEIGHT"]

#: headless Chromium's switches: WebGL on SwiftShader (no GPU needed)
ARGS = ("--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader")
WIDTH, HEIGHT = 1600, 1200           # a still's pixels: 13.5 cm at 300 dpi
NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def chromium() -> str:
    """The path of the system's Chromium (``TACTREC_CHROMIUM`` names another), or one
    :class:`~tactrec.errors.InputError` line saying what to install."""
    named = os.environ.get("TACTREC_CHROMIUM")
    found = shutil.which(named) if named else next((p for p in map(shutil.which, NAMES) if p), None)
    if not found:
        raise InputError("needs Chromium to render a still: install Debian's 'chromium' package "
                         "(or name a browser in TACTREC_CHROMIUM)", "--png")
    return found


def launch(playwright):
    """Headless Chromium launched through ``playwright`` (``sync_playwright()``'s object); one
    :class:`~tactrec.errors.InputError` line if it does not start."""
    from playwright.sync_api import Error

    path = chromium()
    try:
        return playwright.chromium.launch(executable_path=path, args=list(ARGS))
    except Error as exc:
        raise InputError(f"{path} did not start as a headless browser: {_reason(exc)}", "--png") from None


def _reason(exc) -> str:
    """A Playwright error's first line."""
    return (str(exc).strip().splitlines() or ["no reason given"])[0]


def _playwright():
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        raise InputError("needs Playwright to drive the browser: pip install 'tactrec[still]'", "--png") from None
    return sync_playwright


def check_still() -> None:
    """One :class:`~tactrec.errors.InputError` line, before any work, if a still cannot be made here."""
    _playwright()
    chromium()


def render_still(html: str, png, *, width: int = WIDTH, height: int = HEIGHT, timeout: float = 60.0,
                 browser=None) -> None:
    """Render the page text ``html`` (:func:`tactrec.viewer.page.page`) in its still mode and write the
    screenshot to ``png`` (atomically), ``width`` x ``height`` pixels.  ``browser`` is a Playwright
    browser to draw in (one is launched, and closed after, where None)."""
    with tempfile.TemporaryDirectory(prefix="tactrec-still-") as folder:
        page_file = Path(folder) / "view.html"
        page_file.write_text(html, encoding="utf-8")
        if browser is not None:
            data = _shot(browser, page_file, width, height, timeout)
        else:
            with _playwright()() as p:
                chrome = launch(p)
                try:
                    data = _shot(chrome, page_file, width, height, timeout)
                finally:
                    chrome.close()
    write_bytes_atomic(png, data)


def _shot(browser, page_file: Path, width: int, height: int, timeout: float) -> bytes:
    from playwright.sync_api import Error

    try:
        return _screenshot(browser, page_file, width, height, timeout)
    except Error as exc:
        raise InputError(f"the browser could not draw the still: {_reason(exc)}", "--png") from None


def _screenshot(browser, page_file: Path, width: int, height: int, timeout: float) -> bytes:
    context = browser.new_context(viewport={"width": width, "height": height})
    try:
        page = context.new_page()
        page.goto(page_file.as_uri() + "#still")
        page.wait_for_selector("body[data-drawn]", timeout=timeout * 1000)
        return page.locator("#plot").screenshot()
    finally:
        context.close()
