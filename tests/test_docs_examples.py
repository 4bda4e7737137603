"""The documentation's Python examples run as they stand (docs/library.md)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
PAGES = ("library.md",)


def python_blocks(page: str) -> list[str]:
    text = (DOCS / page).read_text(encoding="utf-8")
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


@pytest.mark.parametrize(("page", "index"),
                         [(page, i) for page in PAGES for i in range(len(python_blocks(page)))])
def test_example_runs(page: str, index: int, tmp_path: Path) -> None:
    code = python_blocks(page)[index]
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, f"{page} example {index + 1} failed:\n{done.stderr[-2000:]}"
    assert done.stdout.strip(), f"{page} example {index + 1} printed nothing"


def test_the_library_page_has_examples() -> None:
    assert len(python_blocks("library.md")) >= 4
