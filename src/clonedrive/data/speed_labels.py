"""The expert's target-speed labels: ``target_speed.csv``, a sidecar beside ``driving_log.csv``.

The Udacity log has no column for the speed the driver *meant* to drive, and an eighth column
would break the tools that read the seven fields by position or by a seven-name header (and
would look like a comma-decimal row to a strict reader). So the recorder writes the expert's
speed label into a separate file in the same folder, which Udacity's tools never open::

    center,target_speed_mph
    center_2026_11_21_10_11_12_345.jpg,27.41

- ``center``: the basename of the row's center image, which names the row in ``driving_log.csv``
  whatever path style that file uses;
- ``target_speed_mph``: the speed the expert would aim for at that moment with no set-speed cap
  (its curvature and braking profile, at most the car's top speed), in mph.

A log without the file (a human's or the Udacity simulator's recording), or a row missing from it,
falls back to the row's recorded speed (:func:`label_or_recorded`). Rows are appended and
flushed one at a time, before the log row they belong to, so every log row a killed recorder
left has its label. Bad lines are skipped and counted, never raised.

**Headroom** (:func:`with_headroom`, ``train --speed-headroom H``): on every straight the label
is the top speed, a bound, not the speed the expert would choose. Training on it, a head that is
unsure whether a bend is coming predicts below the top speed, and the policy's cap at the set
speed clips its scatter from above only, so the car drives slower than the expert on open road.
With headroom, such a label continues the expert's own braking profile above the top speed, up
to H times it: ``v = sqrt(v_next^2 + 2 a d)`` back from the next slower label along the
recording (``a``: the expert's planned braking deceleration, ``d``: the distance driven, from the
recorded speeds and times). Labels below the top speed are unchanged, and a label rises
smoothly towards the bend instead of jumping, so the frames before a braking zone are not
pulled faster than the expert brakes.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clonedrive.base.output_files import open_output_fd
from clonedrive.data.line_count import MAX_LOG_ROWS, count_lines

LABELS_NAME = "target_speed.csv"
LABELS_HEADER = "center,target_speed_mph"
#: A labels file larger than this is not read (it would hold far more rows than any log).
MAX_LABELS_BYTES = 256 * 1024**2
#: A label at or above this fraction of the top speed is at the top speed (29.97 mph of 30).
SATURATED_LABEL = 0.999

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


@dataclass
class SpeedLabels:
    """The labels of one folder: center image basename -> target speed [mph]."""

    path: Path
    speeds_mph: dict[str, float] = field(default_factory=dict)
    skipped_lines: int = 0  #: lines that are not ``name,number >= 0``
    warnings: list[str] = field(default_factory=list)


def read_speed_labels(folder: str | os.PathLike) -> SpeedLabels | None:
    """The labels in ``folder/target_speed.csv``, or None if the folder has no such file."""
    path = Path(folder) / LABELS_NAME
    if not path.is_file():
        return None
    labels = SpeedLabels(path)
    size = path.stat().st_size
    if size > MAX_LABELS_BYTES:
        labels.warnings.append(
            f"{path}: {size} bytes is more than {MAX_LABELS_BYTES} ; not read (recorded speeds "
            "stand in for the expert's target speed)")
        return labels
    raw = path.read_bytes()
    line_count = count_lines(raw)
    if line_count > MAX_LOG_ROWS + 1:  # one label per row of the log, and a header
        labels.warnings.append(
            f"{path}: {line_count:,} lines, more than the {MAX_LOG_ROWS:,} rows a driving "
            "log may have; not read (recorded speeds stand in for the expert's target speed)")
        return labels
    text = raw.decode("utf-8", errors="replace")
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")  # as counted
    for number, line in enumerate(lines, start=1):
        fields = [item.strip() for item in line.split(",")]
        if number == 1 and fields == LABELS_HEADER.split(","):
            continue
        if not line.strip():
            continue
        if len(fields) != 2 or not fields[0] or not _NUMBER.fullmatch(fields[1]):
            labels.skipped_lines += 1
            continue
        value = float(fields[1])
        if not math.isfinite(value) or value < 0.0:
            labels.skipped_lines += 1
            continue
        labels.speeds_mph[fields[0]] = value
    if labels.skipped_lines:
        labels.warnings.append(
            f"{path}: {labels.skipped_lines} line(s) are not 'center image,speed >= 0' and were "
            "skipped (their rows use the recorded speed)")
    return labels


def label_or_recorded(target_speed_mph: float | None, speed_mph: float) -> float:
    """The speed label of a log row: the expert's target if recorded, else the recorded speed."""
    return speed_mph if target_speed_mph is None else target_speed_mph


class SpeedLabelWriter:
    """Append ``center,target_speed_mph`` rows to ``folder/target_speed.csv`` (header first when
    the file is new), one ``write`` per row; a torn last line is terminated on reopening."""

    def __init__(self, folder: str | os.PathLike) -> None:
        self.path = Path(folder) / LABELS_NAME
        self.path.parent.mkdir(parents=True, exist_ok=True)
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND
        self._fd: int | None = open_output_fd(self.path, flags)  # no link, no FIFO
        size = os.fstat(self._fd).st_size
        if size == 0:
            self._write(LABELS_HEADER)
        else:
            with open(self.path, "rb") as handle:
                handle.seek(size - 1)
                if handle.read(1) != b"\n":
                    self._write("")  # the torn line becomes one skipped line

    def append(self, center_name: str, target_speed_mph: float) -> None:
        value = float(target_speed_mph)
        if not math.isfinite(value) or value < 0.0:
            raise ValueError(f"target speed {value} mph, expected a finite number >= 0")
        if "," in center_name or "\n" in center_name or "\r" in center_name:
            raise ValueError(f"image name {center_name!r} contains a comma or line break")
        self._write(f"{center_name},{value:.3f}")

    def fileno(self) -> int:
        if self._fd is None:
            raise ValueError(f"{self.path}: writer is closed")
        return self._fd

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def _write(self, line: str) -> None:
        data = (line + "\n").encode("utf-8")
        written = os.write(self.fileno(), data)
        while written < len(data):
            written += os.write(self.fileno(), data[written:])


def with_headroom(labels_mph: np.ndarray, recording: np.ndarray, row: np.ndarray,
                  time_s: np.ndarray, recorded_speed_mph: np.ndarray, headroom: float
                  ) -> tuple[np.ndarray, int]:
    """``(labels [mph], how many were raised)``: each label at the top speed continued above
    it (see the module doc), per sample; samples are grouped into rows by ``(recording, row)``
    and each recording's rows taken in CSV order."""
    from clonedrive.drivers.expert import ExpertConfig
    from clonedrive.network.contract import TARGET_SPEED_SCALE_MPH
    from clonedrive.world.vehicle import MPH_TO_MPS

    labels = np.asarray(labels_mph, dtype=np.float32)
    out = labels.copy()
    top = TARGET_SPEED_SCALE_MPH * MPH_TO_MPS
    ceiling = headroom * top
    decel = ExpertConfig().brake_decel_mps2
    saturated = labels >= np.float32(SATURATED_LABEL * TARGET_SPEED_SCALE_MPH)
    for number in np.unique(recording):
        members = np.flatnonzero(recording == number)
        rows, first, inverse = np.unique(row[members], return_index=True, return_inverse=True)
        picks = members[first]  # one sample per row, rows in CSV order
        speed = np.maximum(np.nan_to_num(recorded_speed_mph[picks].astype(np.float64)), 0.0)
        speed *= MPH_TO_MPS
        step = np.maximum(np.diff(time_s[picks].astype(np.float64)), 0.0)
        gaps = 0.5 * (speed[1:] + speed[:-1]) * step  # metres driven between rows
        bound = np.where(saturated[picks], ceiling, labels[picks] * MPH_TO_MPS)
        profile = bound.copy()
        for index in range(len(rows) - 2, -1, -1):
            reach = math.sqrt(profile[index + 1] ** 2 + 2.0 * decel * gaps[index])
            profile[index] = min(bound[index], reach)
        raised = np.maximum(profile, top) / MPH_TO_MPS
        mask = saturated[members]
        out[members[mask]] = raised[inverse.reshape(-1)][mask].astype(np.float32)
    return out, int(saturated.sum())
