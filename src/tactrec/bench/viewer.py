"""``tactrec bench viewer``: how big ``tactrec show``'s page is and how fast a browser opens and draws it.

For each of the ten ``paper-fig11`` scans, ``instances`` P3 touches (:func:`tactrec.bench.common.vertex_touch`)
are recognised among the ten (``fast``) and each result's page is written (:mod:`tactrec.viewer`: the
five best registered models get a view).  The table gives each page's size and the time to write
it, and the time headless Chromium (the system's, as for ``tactrec show --png``; WebGL on
SwiftShader, its CPU renderer) takes from the start of the page's navigation to its first view drawn
(the page's own clock, ``performance.now()`` when it marks itself drawn), each page opened
``OPENS`` times in a fresh browser context (a cold page each time, the browser already running).
Median, p95 and max of each.  Targets: at most 8 MB and 3 s.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from .common import scan_database, spread, write_json
from .common import vertex_touch

__all__ = ["run", "TARGET_MB", "TARGET_SECONDS", "OPENS"]

TARGET_MB, TARGET_SECONDS = 8.0, 3.0
OPENS = 3                   # opens of each page
WIDTH, HEIGHT = 1200, 800   # the browser window


def _draw_seconds(browser, path: Path) -> float:
    context = browser.new_context(viewport={"width": WIDTH, "height": HEIGHT})
    try:
        page = context.new_page()
        page.goto(path.resolve().as_uri())
        page.wait_for_selector("body[data-drawn]", timeout=120_000)
        return float(page.evaluate("Number(document.body.dataset.drawnMs)")) / 1e3
    finally:
        context.close()


def run(*, out: Path, instances: int, seed: int, jobs=None, quiet: bool = True, **_) -> dict:
    from ..viewer.still import check_still

    check_still()                                   # one line before any work if no browser can draw
    from playwright.sync_api import sync_playwright

    from ..recognition import Recognizer
    from ..surfaces import BUILTIN_SETS
    from ..viewer import page, touch_scene
    from ..viewer.still import launch

    names = BUILTIN_SETS["paper-fig11"]
    db = scan_database(tuple(names))
    models = {e.name: e.model for e in db.entries}
    rows = []
    with tempfile.TemporaryDirectory(prefix="tactrec-bench-viewer-") as folder, \
            Recognizer(db, method="fast") as recognizer, sync_playwright() as p:
        chrome = launch(p)
        try:
            for m, entry in enumerate(db.entries):
                for i in range(instances):
                    touch = vertex_touch(entry, m, i, seed)[1]
                    result = recognizer.recognize(touch).to_json()
                    start = time.perf_counter()
                    text = page(touch_scene(result, touch.curves, models, title=entry.name))
                    path = Path(folder) / f"{entry.name}-{i}.html"
                    path.write_text(text, encoding="utf-8")
                    write = time.perf_counter() - start
                    draws = [_draw_seconds(chrome, path) for _ in range(OPENS)]
                    rows.append({"model": entry.name, "recognized": result["best"], "bytes": path.stat().st_size,
                                 "write_seconds": write, "draw_seconds": draws})
                    if not quiet:
                        print(f"\r{len(rows)}/{len(names) * instances}", end="", file=sys.stderr, flush=True)
        finally:
            chrome.close()
    size = spread([r["bytes"] / 1e6 for r in rows])
    draw = spread([d for r in rows for d in r["draw_seconds"]])
    write = spread([r["write_seconds"] for r in rows])
    table = {"benchmark": "viewer", "instances": instances, "seed": seed, "opens": OPENS, "window": [WIDTH, HEIGHT],
             "size_mb": size, "draw_seconds": draw, "write_seconds": write,
             "targets": {"size_mb": TARGET_MB, "draw_seconds": TARGET_SECONDS}, "rows": rows}
    table["text"] = "\n".join([
        f"tactrec show's page for {len(rows)} P3 results among the ten paper-fig11 scans (fast), "
        f"each opened {OPENS} times in headless Chromium ({WIDTH} x {HEIGHT})",
        f"  size:             median {size['median']:.2f} MB, p95 {size['p95']:.2f} MB, max {size['max']:.2f} MB "
        f"(target <= {TARGET_MB:g} MB)",
        f"  open and draw:    median {draw['median']:.2f} s, p95 {draw['p95']:.2f} s, max {draw['max']:.2f} s "
        f"(target <= {TARGET_SECONDS:g} s)",
        f"  write the page:   median {write['median']:.2f} s, p95 {write['p95']:.2f} s, max {write['max']:.2f} s"])
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "viewer.json", table)
    return table
