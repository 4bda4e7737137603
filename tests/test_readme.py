"""The README stays a front page, and the commands it and the docs show parse as written."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from clonedrive.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
# The front page and the docs; docs/results/ are records of what ran on their day.
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def test_the_readme_is_a_front_page() -> None:
    assert len((ROOT / "README.md").read_bytes()) <= 10_000
    assert max(map(len, (ROOT / "README.md").read_text().splitlines())) <= 400


@pytest.mark.parametrize("page", PAGES, ids=lambda page: page.name)
def test_relative_links_lead_to_files(page: Path) -> None:
    text = page.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
        if "://" not in target:
            assert (page.parent / target).exists(), f"{page.name}: broken link {target}"


def shown_commands(page: Path) -> list[str]:
    """The ``clonedrive ...`` lines of a page's shell blocks, continuation lines joined."""
    text = page.read_text(encoding="utf-8")
    commands = []
    for block in re.findall(r"^```(?:bash|sh)?\n(.*?)^```", text, flags=re.S | re.M):
        for line in block.replace("\\\n", " ").splitlines():
            for part in line.split(" #", 1)[0].split(" && "):
                part = part.split(" | ", 1)[0].rstrip("&").strip()
                words = part.split()
                # "clonedrive web: open this page..." is what a command prints, not a command
                if len(words) >= 2 and words[0] == "clonedrive" and not words[1].endswith(":"):
                    commands.append(part)
    return commands


@pytest.mark.parametrize("page", PAGES, ids=lambda page: page.name)
def test_shown_commands_parse(page: Path) -> None:
    parser = build_parser()
    for command in shown_commands(page):
        argv = shlex.split(command)[1:]
        try:
            parser.parse_args(argv)
        except SystemExit as stop:
            raise AssertionError(f"{page.name}: `{command}` does not parse") from stop


def test_the_readme_shows_the_pipeline() -> None:
    verbs = [command.split()[1] for command in shown_commands(ROOT / "README.md")]
    for verb in ("demo", "record", "check", "train", "evaluate", "report"):
        assert verb in verbs
