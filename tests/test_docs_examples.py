"""Every ```python block of the README and the docs site runs as written, from the project
root, each page's blocks in order in one namespace (a page may build on its earlier blocks)."""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from conftest import PROJECT_ROOT

PAGES = sorted([PROJECT_ROOT / "README.md", *(PROJECT_ROOT / "docs").rglob("*.md")])
BLOCK = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def python_blocks(page: Path) -> list[str]:
    return BLOCK.findall(page.read_text(encoding="utf-8"))


def test_the_docs_have_runnable_examples() -> None:
    assert sum(len(python_blocks(page)) for page in PAGES) >= 2


@pytest.mark.parametrize("page", [p for p in PAGES if python_blocks(p)],
                         ids=lambda p: str(p.relative_to(PROJECT_ROOT)))
def test_code_blocks_run(page: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(PROJECT_ROOT)
    namespace: dict[str, object] = {"__name__": "__docs__"}
    for number, block in enumerate(python_blocks(page), 1):
        exec(compile(block, f"{page.name}, python block {number}", "exec"), namespace)  # noqa: S102


SHELL_BLOCK = re.compile(r"^```sh\n(.*?)^```", re.MULTILINE | re.DOTALL)
COMMANDS = ("cold-eval", "cold-maps", "cold-fuse")


def command_lines(page: Path) -> list[list[str]]:
    """The project's command lines of a page's ```sh blocks, as argument lists (comments and
    line continuations removed)."""
    lines = []
    for block in SHELL_BLOCK.findall(page.read_text(encoding="utf-8")):
        for line in block.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            if words and words[0] in COMMANDS:
                lines.append(words)
    return lines


def parser_of(words: list[str]) -> tuple[argparse.ArgumentParser, list[str]]:
    from cold_maps.cli import evaluate, fuse, maps, sweep

    if words[0] == "cold-eval":
        return (sweep.build_parser(), words[2:]) if words[1:2] == ["sweep"] else (evaluate.build_parser(), words[1:])
    if words[0] == "cold-maps":
        return maps.build_parser(), words[1:]
    return fuse.build_parser(), words[1:]


@pytest.mark.parametrize("page", [p for p in PAGES if command_lines(p)],
                         ids=lambda p: str(p.relative_to(PROJECT_ROOT)))
def test_command_examples_parse(page: Path) -> None:
    """Each documented command line is accepted by the command's own parser (the commands
    themselves run in the CLI tests: whole runs of every example would take minutes)."""
    for words in command_lines(page):
        parser, argv = parser_of(words)
        try:
            parser.parse_args(argv)
        except SystemExit as exc:
            pytest.fail(f"{page.name}: {' '.join(words)!r} is refused by its parser (exit {exc.code})")
