"""The code's shape stays as DESIGN.md and docs/development.md describe it: no module over 500
lines, no two modules that import each other (even inside a function or for type hints only),
and only the entry points at the package's root."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "clonedrive"
MAX_MODULE_LINES = 500
ROOT_MODULES = {"__init__.py", "__main__.py", "cli.py", "envs.py"}


def modules() -> dict[str, Path]:
    found = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        found[name] = path
    return found


def imported(path: Path, known: dict[str, Path]) -> set[str]:
    """The package's modules ``path`` imports, wherever the import statement stands."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return names & set(known)


def test_no_module_is_over_500_lines() -> None:
    long = {name: len(path.read_text(encoding="utf-8").splitlines())
            for name, path in modules().items()}
    assert long  # the package was found
    assert {name: lines for name, lines in long.items() if lines > MAX_MODULE_LINES} == {}


def test_no_two_modules_import_each_other() -> None:
    known = modules()
    edges = {name: imported(path, known) - {name} for name, path in known.items()}
    assert sum(map(len, edges.values())) > 100  # the walk sees the package's imports
    pairs = sorted({tuple(sorted((a, b))) for a, targets in edges.items() for b in targets
                    if a in edges[b]})
    assert pairs == []


def test_only_the_entry_points_sit_at_the_root() -> None:
    assert {path.name for path in PACKAGE.glob("*.py")} == ROOT_MODULES
