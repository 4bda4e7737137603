"""The writer of ``driving_log.csv`` (format and reader: :mod:`clonedrive.data.driving_log`).

:class:`DrivingLogWriter` appends one complete row per call, in a single ``write``, and flushes
it to disk, so a killed recorder leaves a log whose every row is whole; appending to a log that
a killed writer left, it first terminates or truncates an incomplete last line. Numbers are
written as :func:`format_number` gives them.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path

from clonedrive.base.output_files import open_output_fd
from clonedrive.base.paths import with_filename
from clonedrive.data.driving_log import (
    CSV_NAME,
    FIELD_NAMES,
    FIELD_RANGES,
    HEADER_LINE,
    IMAGE_FOLDER,
    NUMBER,
    RANGE_TOLERANCE,
    image_basename,
)

logger = logging.getLogger(__name__)


def format_number(value: float) -> str:
    """A number as the log stores it: up to 7 significant digits, no trailing zeros
    (``0``, ``-0.2345``, ``4.770404e-05``)."""
    return format(float(value) + 0.0, ".7g")


class DrivingLogWriter:
    """Append rows to ``<folder>/driving_log.csv`` in the simulator's format, one complete row
    per :meth:`append`, each written with a single ``write`` call and then ``os.fsync``-ed.

    Rows are seven unquoted fields, ``\\n``-terminated; numbers use :func:`format_number`.
    Image paths are written absolute (as the simulator does) or, with ``relative_paths=True``,
    as ``IMG/<basename>``. Either way the reader finds an image at ``<folder>/IMG/<basename>``,
    so images must be written there (this writer creates ``IMG/``). A relative path given to
    :meth:`append` is taken relative to ``folder``.

    Crash safety: a process killed mid-row can leave at most one incomplete last line. When
    appending to an existing log whose last line has no newline, the writer looks at that line:
    if it is a whole, parseable row (a log from a tool that omits the final newline) it is
    kept and terminated with ``\\n``; otherwise it is a torn write and is truncated away. Either
    way ``repaired_tail`` says what was done and a warning is logged.

    ``header=True`` writes ``center,left,right,steering,throttle,brake,speed`` first, only
    when the file is new or empty. ``append=False`` starts a new file, replacing any old one.
    ``fsync=False`` skips the per-row fsync (the row is still written in one call).
    """

    def __init__(
        self,
        folder: str | os.PathLike,
        *,
        header: bool = False,
        relative_paths: bool = False,
        append: bool = True,
        fsync: bool = True,
    ) -> None:
        self.folder = Path(folder).absolute()
        self.csv_path = self.folder / CSV_NAME
        self.relative_paths = relative_paths
        self.fsync = fsync
        self.rows_written = 0
        self.repaired_tail: str | None = None  # "terminated" / "truncated" / None
        if not relative_paths:
            _check_path_text(str(self.folder), "log folder (use relative_paths=True)")
        (self.folder / IMAGE_FOLDER).mkdir(parents=True, exist_ok=True)

        existed = self.csv_path.exists()
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND
        if not append:
            flags |= os.O_TRUNC
        # Never append through a link planted at the log's name (output_files).
        self._fd: int | None = open_output_fd(self.csv_path, flags)
        if append and existed:
            self._repair_tail()
        if not existed and os.name == "posix":
            _fsync_directory(self.folder)
        if header and os.fstat(self._fd).st_size == 0:
            self._write_line(HEADER_LINE)

    def append(
        self,
        center: Path,
        left: Path,
        right: Path,
        steering: float,
        throttle: float,
        brake: float,
        speed_mph: float,
    ) -> None:
        """Write one row and flush it to disk. Raises ValueError for a value the reader would
        reject (non-finite or out of range) or a path that would break the CSV row."""
        if self._fd is None:
            raise ValueError(f"{self.csv_path}: writer is closed")
        values = (steering, throttle, brake, speed_mph)
        for (name, _index, low, high), value in zip(FIELD_RANGES, values, strict=True):
            value = float(value)
            if not math.isfinite(value):
                raise ValueError(f"{name} is {value}, expected a finite number")
            if (low is not None and value < low - RANGE_TOLERANCE) or (
                high is not None and value > high + RANGE_TOLERANCE
            ):
                expected = f"[{low:g}, {high:g}]" if high is not None else f">= {low:g}"
                raise ValueError(f"{name} is {value:g}, expected {expected}")
        path_texts = [self._path_text(Path(path)) for path in (center, left, right)]
        self._write_line(",".join([*path_texts, *(format_number(value) for value in values)]))
        self.rows_written += 1

    def close(self) -> None:
        """Close the file (idempotent)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> DrivingLogWriter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _path_text(self, path: Path) -> str:
        if self.relative_paths:
            text = f"{IMAGE_FOLDER}/{path.name}"
        else:
            text = str(path if path.is_absolute() else self.folder / path)
        _check_path_text(text, "image path")
        return text

    def _write_line(self, line: str) -> None:
        data = (line + "\n").encode("utf-8")
        try:
            written = os.write(self._fd, data)
            while written < len(data):  # a short write to a regular file is rare; finish it
                written += os.write(self._fd, data[written:])
            if self.fsync:
                os.fsync(self._fd)
        except OSError as error:  # ENOSPC and friends name no file: name the log
            raise with_filename(error, self.csv_path) from None

    def _repair_tail(self) -> None:
        """Terminate or truncate an incomplete last line left by a killed writer."""
        with open(self.csv_path, "rb") as handle:
            handle.seek(0, os.SEEK_END)
            size = handle.tell()
            if size == 0:
                return
            handle.seek(size - 1)
            if handle.read(1) == b"\n":
                return
            start = max(0, size - 65536)
            handle.seek(start)
            tail = handle.read()
        newline = tail.rfind(b"\n")
        if newline < 0 and start > 0:
            raise ValueError(f"{self.csv_path}: last line is longer than 64 KiB; not a log?")
        keep = start + newline + 1  # 0 when the file holds a single incomplete line
        partial = tail[newline + 1 :].decode("utf-8", errors="replace")
        fields = partial.rstrip("\r").split(",")
        if _looks_whole(fields):
            self._write_line("")
            self.repaired_tail = "terminated"
            logger.warning("%s: last line had no newline; terminated it", self.csv_path)
        else:
            os.truncate(self.csv_path, keep)
            self.repaired_tail = "truncated"
            logger.warning(
                "%s: removed an incomplete last line (%d bytes) left by an interrupted write",
                self.csv_path,
                size - keep,
            )


def _looks_whole(fields: list[str]) -> bool:
    """True if ``fields`` form a complete row (header or data), not a torn write."""
    if len(fields) == len(FIELD_NAMES) and [item.strip() for item in fields] == list(FIELD_NAMES):
        return True
    if len(fields) != len(FIELD_NAMES):
        return False
    if not all(image_basename(item) for item in fields[:3]):
        return False
    return all(NUMBER.fullmatch(item.strip()) for item in fields[3:])


def _check_path_text(text: str, what: str) -> None:
    if "," in text or "\n" in text or "\r" in text:
        raise ValueError(
            f"{what} {text!r} contains a comma or line break, which would break the "
            "unquoted CSV row"
        )


def _fsync_directory(folder: Path) -> None:
    """Make a newly created file's directory entry durable (POSIX only)."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
