"""``tactrec bench report``: every benchmark's latest table and plots in one offline page, each with the
command that made it and when; opened in headless Chromium, it fetches nothing and shows its plots."""

import html
import json

import pytest

from tactrec.cli import main


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """paper-example (a table with the paper's numbers beside ours) run into a folder; a field
    table whose run made a plot; a table from a version that recorded no run; one whose name is markup."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tactrec.bench.report import record_run

    out = tmp_path_factory.mktemp("bench-out")
    assert main(["bench", "paper-example", "--instances", "2", "--out", str(out), "--quiet"]) == 0
    fig, ax = plt.subplots(figsize=(4, 3))
    ax.plot([0, 1], [1, 0])
    fig.savefig(out / "field-errors.png")
    plt.close(fig)
    (out / "field.json").write_text(json.dumps({"benchmark": "field"}), encoding="utf-8")
    record_run(out / "field.json", command="tactrec bench field", text="a < b & c", plots=[out / "field-errors.png"])
    (out / "serve.json").write_text(json.dumps({"benchmark": "serve", "requests": 1}), encoding="utf-8")
    odd = {"benchmark": "kernels", "run": {"command": "tactrec bench kernels", "date": "now", "text": "", "plots": None}}
    (out / "kernels-<i>odd.json").write_text(json.dumps(odd), encoding="utf-8")
    return out


def test_each_run_records_its_command_date_and_table(folder):
    run = json.loads((folder / "paper-example.json").read_text(encoding="utf-8"))["run"]
    assert run["command"].startswith("tactrec bench paper-example --instances 2 --out ")
    assert run["date"].endswith("+00:00") and "paper" in run["text"]


def test_the_report_holds_every_table_and_plot_and_names_what_was_not_run(folder, capsys):
    capsys.readouterr()
    assert main(["bench", "report", "--out", str(folder)]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {folder / 'report.html'}"
    text = (folder / "report.html").read_text(encoding="utf-8")
    for name in ("paper-example", "field"):
        run = json.loads((folder / f"{name}.json").read_text(encoding="utf-8"))["run"]
        assert f'<section id="{name}">' in text and run["date"] in text
        assert html.escape(run["text"]) in text
    assert text.count('src="data:image/png;base64,') == 1 and "a &lt; b &amp; c" in text
    assert "did not record its command" in text                                   # serve.json, an older run
    assert "<code>tactrec bench sensor</code>" in text                            # not run yet
    assert "http://" not in text and "https://" not in text
    # a file's name is text, never markup; a run without plots has none
    assert "<i>odd" not in text and 'id="kernels-&lt;i&gt;odd"' in text


def test_the_report_opens_offline_in_a_browser(folder):
    """In headless Chromium: no console error, no request beyond its file, every plot decoded."""
    import shutil

    from playwright.sync_api import sync_playwright

    from tactrec.viewer import still

    assert shutil.which("chromium"), "chromium not found: 'make test' installs Debian's chromium package"
    main(["bench", "report", "--out", str(folder)])
    url = (folder / "report.html").resolve().as_uri()
    errors, requests = [], []
    with sync_playwright() as p:
        browser = still.launch(p)
        try:
            page = browser.new_page()
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.on("request", lambda r: requests.append(r.url) if r.url != url and not r.url.startswith("data:")
                    else None)
            page.goto(url)
            page.wait_for_load_state("load")
            widths = page.eval_on_selector_all("img", "els => els.map(e => e.naturalWidth)")
        finally:
            browser.close()
    assert errors == [] and requests == []
    assert widths == [400]
