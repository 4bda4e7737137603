"""A bench run's ``bench.json`` as ``bench compare`` and ``bench merge`` are given it: the folder
holding it, or the file itself."""

from __future__ import annotations

from pathlib import Path


class BenchFileError(ValueError):
    """No bench.json where one was named, or a file that is not one; the message names it."""


def read_bench_file(path_text: str, spec: str) -> tuple[Path, dict]:
    """(the file, its content) of the bench run at ``path_text`` (``spec``: what the user wrote,
    for the message)."""
    from clonedrive.base.config import read_json

    path = Path(path_text)
    path = path / "bench.json" if path.is_dir() else path
    if not path.is_file():
        raise BenchFileError(f"{spec}: no bench.json there")
    report = read_json(path, what="bench.json")
    if not isinstance(report, dict):
        raise BenchFileError(f"{path}: not a bench.json (its top level is not an object)")
    return path, report


def prediction_of(report: dict) -> str:
    """How the bench run's network policy put frames through the network (bench.json's
    ``prediction``; a run made before it was recorded batched the lock-step cars' frames)."""
    from clonedrive.drivers.policy import PREDICTION_BEFORE

    value = report.get("prediction")
    return value if isinstance(value, str) and value else PREDICTION_BEFORE
