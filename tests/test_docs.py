"""The README and docs/ point at what exists: every relative link at a file there (and a heading of
it, where the link names one), every `tactrec COMMAND` at a command of the CLI, every `tactrec
bench NAME` at a benchmark, every repository path they quote at a file, and every module, class or
function of the package they name (`tactrec.x.y`) at one that is there."""

import importlib

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


def _quoted_commands(text: str) -> list[str]:
    """Every ``tactrec ...`` command a page quotes, in backticks or on a line of a code block."""
    found = re.findall(r"`(tactrec [^`\n]+)`", text)
    for block in re.findall(r"```(?:sh|bash|console)?\n(.*?)```", text, flags=re.S):
        found += [line.strip() for line in block.splitlines() if line.strip().startswith("tactrec ")]
    return found


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_option_of_a_quoted_command_is_one_of_its_options(page):
    """``tactrec recognize DATA --db DB --json``: each ``--option`` a page gives a command is one the
    command takes (the words in between are the page's placeholders)."""
    commands = _subcommands(build_parser())
    wrong = []
    for quoted in _quoted_commands(page.read_text(encoding="utf-8")):
        words = quoted.split("  #")[0].split()
        parser = commands.get(words[1]) if len(words) > 1 else None
        if parser is None:
            continue
        known = {option for action in parser._actions for option in action.option_strings}
        for word in words[2:]:
            option = re.match(r"[\[(]*(--[a-z][a-z-]*)", word)
            if option and option.group(1) not in known:
                wrong.append(f"{quoted!r}: {option.group(1)}")
    assert not wrong, f"{page.name}: options no command takes: " + "; ".join(wrong)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_repository_path_quoted_exists(page):
    text = page.read_text(encoding="utf-8")
    for path in re.findall(r"`((?:examples|docs|src|tests)/[\w./-]+\.\w+)`", text):
        assert (ROOT / path).exists(), f"{page.name}: `{path}`: no such file"
    for path in re.findall(r"`(tactrec/[\w./-]+\.py)`", text):
        assert (ROOT / "src" / path).exists(), f"{page.name}: `{path}`: no such file"


def _named(dotted: str) -> bool:
    """Whether ``dotted`` (``tactrec.x.y``) is a module of the package or a name in one (an
    attribute a class declares or sets on its instances included)."""
    import inspect

    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            found = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for attribute in parts[k:]:
            if hasattr(found, attribute):
                found = getattr(found, attribute)
                continue
            source = inspect.getsource(found) if inspect.isclass(found) else ""
            return bool(re.search(rf"(self\.{attribute}\b|^\s+{attribute}\s*:)", source, flags=re.M))
        return True
    return False


def test_every_reference_in_a_docstring_names_a_part_of_the_package():
    """The sources' own references (``:func:`tactrec.x.y```, ``:mod:`.sibling```) name what is there:
    a module moved or a function renamed leaves no reference behind."""
    src = ROOT / "src"
    wrong = []
    for path in sorted((src / "tactrec").rglob("*.py")):
        module = ".".join(path.relative_to(src).with_suffix("").parts).removesuffix(".__init__")
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        text = path.read_text(encoding="utf-8")
        for found in re.finditer(r":(?:func|mod|class|meth|data|attr|exc):`~?(\.*)(tactrec\.[\w.]+|[\w.]+)`", text):
            dots, name = found.groups()
            if not dots and not name.startswith("tactrec."):
                continue                                          # a name of the module itself, or numpy's
            if dots:
                name = ".".join(package.split(".")[:len(package.split(".")) - len(dots) + 1] + [name])
            if not _named(name):
                wrong.append(f"{path.relative_to(ROOT)}:{text[:found.start()].count(chr(10)) + 1}: {found.group(0)}")
    assert not wrong, "references to nothing:\n" + "\n".join(wrong)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_part_of_the_package_named_exists(page):
    text = page.read_text(encoding="utf-8")
    missing = sorted({name for name in re.findall(r"`(tactrec(?:\.\w+)+)", text) if not _named(name)})
    assert not missing, f"{page.name}: no such part of the package: {', '.join(missing)}"


def test_a_newcomer_finds_set_up_a_python_call_and_the_result_in_the_readmes_first_hundred_lines():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 250
    head = "\n".join(lines[:100])
    assert "make demo" in head and "make test" in head
    assert "import tactrec" in head and "tactrec.recognize(" in head
    assert "## The result" in head and '"ranking"' in head
