"""``history.csv``, a training run's loss per epoch: the one writer and the one reader.

One row per finished epoch, columns :data:`HISTORY_COLUMNS`: ``epoch`` (1-based), ``loss`` and
``val_loss`` (both include the L2 penalty), ``mse`` and ``val_mse`` (plain mean squared
steering error), ``seconds`` (the epoch's wall time); a run with a speed head adds
:data:`SPEED_HISTORY_COLUMNS` (mean squared error of the normalised target speed). Training
rewrites the file atomically after every epoch; ``train --resume`` and the report read it back.
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

from clonedrive.base.config import write_text_atomic

HISTORY_NAME = "history.csv"
HISTORY_COLUMNS = ("epoch", "loss", "val_loss", "mse", "val_mse", "seconds")
#: Written after HISTORY_COLUMNS when the rows hold them (runs with a speed head).
SPEED_HISTORY_COLUMNS = ("speed_mse", "val_speed_mse")


def write_history(path: str | os.PathLike, history: list[dict]) -> Path:
    """Write ``history`` (dicts holding at least :data:`HISTORY_COLUMNS`) atomically."""
    buffer = io.StringIO()
    columns = HISTORY_COLUMNS
    if history and all(key in history[0] for key in SPEED_HISTORY_COLUMNS):
        columns = HISTORY_COLUMNS + SPEED_HISTORY_COLUMNS
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for row in history:
        writer.writerow({key: row[key] for key in columns})
    return write_text_atomic(path, buffer.getvalue())


def read_history(path: str | os.PathLike) -> list[dict]:
    """The rows of a ``history.csv`` as dicts of floats, ``epoch`` an int; ``[]`` when there
    is no such file. A cell that is not a number becomes NaN; a row without a usable epoch is
    left out, and cells beyond the header are ignored."""
    path = Path(path)
    if not path.is_file():
        return []
    rows = []
    with open(path, encoding="utf-8", newline="") as handle:
        for row in csv.DictReader(handle):
            parsed: dict = {}
            for key, value in row.items():
                if key is None:
                    continue
                try:
                    parsed[key] = float(value)
                except (TypeError, ValueError):
                    parsed[key] = math.nan
            if math.isfinite(parsed.get("epoch", math.nan)):
                parsed["epoch"] = int(parsed["epoch"])
                rows.append(parsed)
    return rows
