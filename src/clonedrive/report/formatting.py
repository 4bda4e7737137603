"""How the write-up prints numbers, shapes, runs and paths (used as ``fmt.num(...)`` etc.)."""

from __future__ import annotations

import math
from pathlib import Path

#: What a table shows for a value that is missing or not finite.
MISSING = "–"


def num(value, digits: int = 2, missing: str = MISSING) -> str:
    """``value`` with ``digits`` decimals and thousands separators; ``missing`` for None,
    NaN or infinity; text that is not a number as it is."""
    return _formatted(value, f",.{digits}f", missing)


def sig(value, digits: int = 3, missing: str = MISSING) -> str:
    """``value`` with ``digits`` significant digits (``0.00526``), for figures too small for a
    fixed number of decimals; ``missing`` and text that is not a number as :func:`num`."""
    return _formatted(value, f".{digits}g", missing)


def _formatted(value, spec: str, missing: str) -> str:
    """``value`` in the format ``spec``; ``missing`` for None, NaN or infinity; text that is
    not a number as it is."""
    if value is None:
        return missing
    try:
        number = float(value)
    except (TypeError, ValueError):
        return str(value)
    return format(number, spec) if math.isfinite(number) else missing


def signed(value: float, digits: int = 2) -> str:
    """``value`` with its sign always shown (``+0.25``)."""
    return f"{value:+.{digits}f}"


def count(value) -> str:
    """A whole number with thousands separators, or :data:`MISSING`."""
    return f"{int(value):,}" if value is not None else MISSING


def shape(dims) -> str:
    """A Keras shape without its batch axis, ``160 × 320 × 3``; ``?`` for unknown sizes."""
    return " × ".join("?" if d is None else str(d) for d in tuple(dims)[1:]) or "scalar"


def track_label(run: dict) -> str:
    """An evaluation run's track, marked ``(unseen)`` for a generated test track."""
    return f"{run.get('track', '?')}" + (" (unseen)" if run.get("unseen") else "")


def run_label(run: dict) -> str:
    """``lake at 15 mph``."""
    return f"{track_label(run)} at {float(run.get('speed_mph', 0)):g} mph"


def plural(number: int, word: str) -> str:
    """``1 recording``, ``3 recordings``."""
    return f"{number:,} {word}{'' if number == 1 else 's'}"


def listed(items: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    if len(items) <= 1:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]


def relative(path: Path, base: Path) -> str:
    """``path`` relative to ``base`` when it lies inside it, else as it is."""
    try:
        return path.resolve().relative_to(base.resolve()).as_posix() or "."
    except ValueError:
        return str(path)
