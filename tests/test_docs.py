"""The README and docs/ point at what exists: every relative link at a file there (and a heading of
it, where the link names one), every `tactrec COMMAND` at a command of the CLI, every `tactrec
bench NAME` at a benchmark, and every repository path they quote at a file."""

import argparse
import re
from pathlib import Path

import pytest

from tactrec.bench import BENCHMARKS
from tactrec.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _slug(heading: str) -> str:
    """A heading's anchor as GitHub makes it: lower case, punctuation but hyphens and underscores
    dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return {_slug(m.group(1)) for m in re.finditer(r"^#+ (.+)$", text, flags=re.M)}


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_relative_link_reaches_a_file_and_its_heading(page):
    text = page.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue                                           # a web address
        path, _, anchor = target.partition("#")
        file = page if not path else (page.parent / path).resolve()
        assert file.exists(), f"{page.name}: link to {target}: no such file"
        if anchor and file.suffix == ".md":
            assert anchor in _anchors(file), f"{page.name}: link to {target}: no such heading"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_command_and_benchmark_named_exists(page):
    commands = _subcommands(build_parser())
    benches = set(BENCHMARKS) | {"report"}
    text = page.read_text(encoding="utf-8")
    for name in re.findall(r"`tactrec ([a-z][a-z-]*)", text):
        assert name in commands, f"{page.name}: `tactrec {name}` is no command"
    for name in re.findall(r"`tactrec bench ([a-z0-9][a-z0-9-]*)", text):
        assert name in benches, f"{page.name}: `tactrec bench {name}` is no benchmark"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_repository_path_quoted_exists(page):
    text = page.read_text(encoding="utf-8")
    for path in re.findall(r"`((?:examples|docs|src|tests)/[\w./-]+\.\w+)`", text):
        assert (ROOT / path).exists(), f"{page.name}: `{path}`: no such file"
