"""``tactrec bench report``: every benchmark's latest table and plots in one offline HTML page.

Each ``tactrec bench NAME`` run records, in its ``NAME.json`` under ``"run"``, the command that made
it, when (UTC) and its printed table (the paper's numbers beside ours where the paper has them;
:func:`record_run`).  The report reads a folder of these (``bench-out`` by default) and writes one
page: for each benchmark of :data:`tactrec.bench.BENCHMARKS` that has a table, its summary, the
command and the date, the table and its plots (PNG files inlined as ``data:`` URLs: the page makes
no network request); then the benchmarks not run yet, each with the command that runs it.
"""

from __future__ import annotations

import base64
import datetime
import html
import json
from pathlib import Path

from ..errors import InputError
from ..io.atomic import write_text_atomic

__all__ = ["record_run", "report_page", "write_report", "REPORT"]

REPORT = "report.html"

_STYLE = """
body { font: 15px sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; color: #222; }
pre { background: #f6f6f6; padding: 10px; overflow-x: auto; font-size: 12px; line-height: 1.35; }
code { background: #f0f0f0; padding: 1px 4px; }
section { border-top: 1px solid #ddd; margin-top: 2em; }
img { max-width: 100%; display: block; margin: 1em 0; }
.meta { color: #555; font-size: 13px; }
"""


def record_run(path: Path, *, command: str, text: str, plots=()) -> None:
    """Add ``"run"`` (``command``, UTC ``date``, the printed table ``text``, ``plots``' file names) to the
    benchmark's JSON at ``path`` (rewritten atomically)."""
    from .common import write_json

    table = json.loads(path.read_text(encoding="utf-8"))
    table["run"] = {"command": command, "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                    "text": text, "plots": [Path(p).name for p in plots]}
    write_json(path, table)


def _read(path: Path) -> dict:
    try:
        table = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a benchmark's table: {exc}", path) from None
    if not isinstance(table, dict):
        raise InputError("not a benchmark's table: not a JSON object", path)
    return table


def _png(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _benchmark_of(stem: str, names) -> str | None:
    """The benchmark a table's file is of: the longest name its stem starts with (``paper-fig11`` for
    ``paper-fig11-paper-like.json``)."""
    found = [n for n in names if stem == n or stem.startswith(n + "-")]
    return max(found, key=len) if found else None


def _section(path: Path, name: str, summary: str, folder: Path) -> str:
    run = _read(path).get("run")
    stem = html.escape(path.stem, quote=True)
    parts = [f"<section id=\"{stem}\"><h2>{stem}</h2><p>{html.escape(summary)}</p>"]
    if not isinstance(run, dict):
        date = datetime.datetime.fromtimestamp(path.stat().st_mtime, datetime.timezone.utc)
        parts.append(f"<p class=\"meta\">{html.escape(path.name)} written {date.isoformat(timespec='seconds')} by a "
                     f"version that did not record its command or table: run <code>tactrec bench {name}</code> "
                     "again to see it here.</p>")
        return "".join(parts) + "</section>"
    parts.append(f"<p class=\"meta\">made by <code>{html.escape(str(run.get('command', '')))}</code> on "
                 f"{html.escape(str(run.get('date', '')))}</p><pre>{html.escape(str(run.get('text', '')))}</pre>")
    plots = run.get("plots")
    for plot in plots if isinstance(plots, list) else []:
        image = folder / Path(str(plot)).name
        if image.suffix.lower() == ".png" and image.exists():
            parts.append(f"<img alt=\"{html.escape(image.name)}\" src=\"{_png(image)}\">")
        else:
            parts.append(f"<p class=\"meta\">{html.escape(image.name)}: missing</p>")
    return "".join(parts) + "</section>"


def report_page(folder: Path) -> str:
    """The report's HTML text for the tables in ``folder``: benchmarks in :data:`~tactrec.bench.BENCHMARKS`'
    order, each variant's table (``--scans``, a method) in its own section."""
    from . import BENCHMARKS

    tables = {}
    for path in sorted(folder.glob("*.json")):
        name = _benchmark_of(path.stem, BENCHMARKS)
        if name is not None:
            tables.setdefault(name, []).append(path)
    made = [_section(path, name, BENCHMARKS[name].summary, folder) for name in BENCHMARKS for path in tables.get(name, [])]
    contents = "".join(f"<li><a href=\"#{html.escape(p.stem, quote=True)}\">{html.escape(p.stem)}</a></li>"
                       for n in BENCHMARKS for p in tables.get(n, []))
    waiting = "".join(f"<li><code>tactrec bench {n}</code>: {html.escape(b.summary)}</li>"
                      for n, b in BENCHMARKS.items() if n not in tables)
    now = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>tactrec benchmarks</title>"
            f"<style>{_STYLE}</style></head><body><h1>tactrec benchmarks</h1>"
            f"<p class=\"meta\">The latest table of each benchmark in {html.escape(folder.name)}/, gathered {now}. "
            "Where the paper reports a figure, the table prints it beside ours (<code>paper</code>).</p>"
            f"<ul>{contents}</ul>{''.join(made)}"
            + (f"<section id=\"not-run\"><h2>Not run yet</h2><ul>{waiting}</ul></section>" if waiting else "")
            + "</body></html>\n")


def write_report(folder, out=None) -> Path:
    """Write the report of the tables in ``folder`` to ``out`` (default ``folder/report.html``)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("no such folder: run a benchmark first (tactrec bench NAME)", folder)
    out = Path(out) if out is not None else folder / REPORT
    write_text_atomic(out, report_page(folder))
    return out
