"""The Udacity ``driving_log.csv`` format and its reader: with
:mod:`clonedrive.data.log_writer`, the only code that reads or writes it.

A log is a folder holding ``driving_log.csv`` and ``IMG/``. Each CSV row has seven unquoted
fields ``center,left,right,steering,throttle,brake,speed``:

- image paths as the recording machine wrote them (absolute POSIX, absolute Windows with ``\\``
  or ``C:/``, or relative ``IMG/...``, sometimes after a leading space); every one is resolved
  to ``<log folder>/IMG/<basename>``;
- steering in [-1, 1] (= wheel angle / 25 deg), throttle and brake in [0, 1], speed in mph;
  numbers as C# writes them (``0``, ``-0.2924528``, ``4.770404E-05``).

The reader accepts every variant real users have (header or none, CRLF and LF mixed, blank lines,
extra trailing spreadsheet columns, side-camera images left out of a shared data set) and never
raises on a bad row: it skips the row and says why, with the 1-based line number. A row whose
center image exists but whose left or right image does not is kept for the cameras it has
(``LogRow.cameras``), and counted. A file that is not a log at all -- UTF-16 text, an image,
binary data, larger than :data:`MAX_LOG_BYTES` -- raises :class:`DrivingLogError` naming it.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from datetime import datetime, timedelta
from pathlib import Path

from clonedrive.base.images import ImageDecodeError, decode_rgb
from clonedrive.base.udacity_spec import IMAGE_SHAPE
from clonedrive.data.line_count import MAX_LOG_ROWS, count_lines

CAMERAS = ("center", "left", "right")
CSV_NAME = "driving_log.csv"
IMAGE_FOLDER = "IMG"
FIELD_NAMES = ("center", "left", "right", "steering", "throttle", "brake", "speed")
HEADER_LINE = ",".join(FIELD_NAMES)

# Values this far outside their range still count as in range (float32 printing noise);
# they are clamped to the range.
RANGE_TOLERANCE = 1e-3
VERIFY_MODES = ("none", "exists", "decode")
#: Largest driving_log.csv read [bytes]: about 300,000 rows of absolute paths, 5.5 hours at
#: 15 Hz (the Udacity sample data set is 1.5 MB). Reading one at the cap peaks near 0.6 GB.
MAX_LOG_BYTES = 64 << 20
#: Bins of the steering histogram ``record`` and ``check`` print (over [-1, 1]).
STEERING_HISTOGRAM_BINS = 11
#: Longest image file name [bytes] that file systems allow.
MAX_NAME_BYTES = 255
# What a file that is not a CSV starts with, and what it is then.
_MAGIC = ((b"\xff\xd8\xff", "a JPEG image"), (b"\x89PNG", "a PNG image"),
          (b"PK\x03\x04", "a zip file (a .keras model?)"), (b"\x89HDF", "an HDF5 file (a model?)"),
          (b"GIF8", "a GIF image"))

#: A number as C# writes it (``0``, ``-0.2924528``, ``4.770404E-05``).
NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_NON_FINITE = re.compile(r"[+-]?(?:nan|inf|infinity|\u221e)", re.IGNORECASE)
_IMAGE_TIME = re.compile(
    r"(?:center|left|right)_(\d{4})_(\d{2})_(\d{2})_(\d{2})_(\d{2})_(\d{2})_(\d{3})\.\w+$"
)
#: (field name, index, lowest, highest) of the numeric fields; None = unbounded.
FIELD_RANGES = (
    ("steering", 3, -1.0, 1.0),
    ("throttle", 4, 0.0, 1.0),
    ("brake", 5, 0.0, 1.0),
    ("speed", 6, 0.0, None),
)


@dataclass(frozen=True)
class LogRow:
    """One usable sample."""

    row: int  # 1-based line number in the CSV file
    center: Path  # resolved to <log dir>/IMG/<basename>
    left: Path
    right: Path
    steering: float  # [-1, 1] = wheel angle / 25 deg
    throttle: float  # [0, 1]
    brake: float  # [0, 1]
    speed_mph: float
    #: The cameras whose images are usable: all three, or fewer when a side image is missing.
    cameras: tuple[str, ...] = CAMERAS
    #: the expert's target speed from the ``target_speed.csv`` sidecar (data.speed_labels);
    #: None when the log has none (human and Udacity logs): the recorded speed stands in
    target_speed_mph: float | None = None

    def image(self, camera: str) -> Path:
        """The image path of ``camera`` (one of :data:`CAMERAS`)."""
        if camera not in CAMERAS:
            raise ValueError(f"unknown camera {camera!r}; expected one of {', '.join(CAMERAS)}")
        return getattr(self, camera)


@dataclass(frozen=True)
class SkippedRow:
    """A row the reader could not use.

    ``reason`` is a category key: ``field_count``, ``non_numeric`` (includes NaN and infinity),
    ``out_of_range``, ``image_missing`` (the center image; a missing side image only turns that
    camera off), ``image_name`` (longer than a file system allows), ``image_corrupt``,
    ``image_size`` (decodes, but is not 320x160x3) or ``empty`` (a blank line).
    """

    row: int
    reason: str
    detail: str  # human sentence naming the field/file


class DrivingLogError(ValueError):
    """A file that cannot be read as a driving log at all; the message names it and says why."""


@dataclass
class DrivingLog:
    """A read log: the usable rows, the skipped ones, and file-level warnings."""

    folder: Path
    csv_path: Path
    rows: list[LogRow]
    skipped: list[SkippedRow]
    total_rows: int  # data rows seen (header excluded) = len(rows) + len(skipped)
    has_header: bool
    # File-level notes that skip no row: not UTF-8, a repeated header line.
    warnings: list[str] = field(default_factory=list)

    @property
    def side_images_missing(self) -> int:
        """Usable rows with a side camera off (its image missing): used for fewer cameras."""
        return sum(1 for row in self.rows if len(row.cameras) < len(CAMERAS))

    def shared_images(self) -> dict[Path, list[int]]:
        """Image files that more than one usable row names -> those rows' line numbers (two
        recorders writing into one folder overwrite each other's images)."""
        users: dict[Path, list[int]] = {}
        for row in self.rows:
            for camera in row.cameras:
                users.setdefault(row.image(camera), []).append(row.row)
        return {path: rows for path, rows in users.items() if len(rows) > 1}

    def skipped_by_reason(self) -> dict[str, list[SkippedRow]]:
        """Skipped rows grouped by reason, reasons in order of first appearance."""
        groups: dict[str, list[SkippedRow]] = {}
        for skipped in self.skipped:
            groups.setdefault(skipped.reason, []).append(skipped)
        return groups


def resolve_csv_path(path: str | os.PathLike) -> Path:
    """``path/driving_log.csv`` if ``path`` is a folder, else ``path`` (the CSV itself)."""
    path = Path(path)
    return path / CSV_NAME if path.is_dir() else path


def image_basename(recorded_path: str) -> str:
    """The file name of a path as any OS wrote it (``/``, ``\\`` or ``C:/`` separators)."""
    return re.split(r"[\\/]", recorded_path.strip())[-1]


def image_name(camera: str, start: datetime, elapsed_s: float) -> str:
    """The simulator's image file name for ``camera`` at ``start + elapsed_s`` seconds.

    ``image_name("center", datetime(2026, 11, 21, 10, 11, 12), 0.345)`` is
    ``"center_2026_11_21_10_11_12_345.jpg"`` (milliseconds truncated, as the simulator does).
    """
    if camera not in CAMERAS:
        raise ValueError(f"unknown camera {camera!r}; expected one of {', '.join(CAMERAS)}")
    moment = start + timedelta(seconds=elapsed_s)
    return f"{camera}_{moment:%Y_%m_%d_%H_%M_%S}_{moment.microsecond // 1000:03d}.jpg"


def image_time(name: str | os.PathLike) -> datetime | None:
    """The timestamp in a simulator image name (``center_2017_07_22_10_11_12_345.jpg``), or
    None if the name does not carry one."""
    match = _IMAGE_TIME.search(image_basename(os.fspath(name)))
    if match is None:
        return None
    year, month, day, hour, minute, second, millis = (int(part) for part in match.groups())
    try:
        return datetime(year, month, day, hour, minute, second, millis * 1000)
    except ValueError:  # e.g. month 13: a name that only looks like a timestamp
        return None


def read_driving_log(
    path: str | os.PathLike, *, verify_images: str = "exists", progress: bool = False
) -> DrivingLog:
    """Read a Udacity-format log.

    Args:
        path: the folder holding ``driving_log.csv``, or the CSV file itself.
        verify_images: ``"none"`` (trust the paths), ``"exists"`` (each of the three images must
            be a file) or ``"decode"`` (each must also decode with OpenCV; a size other than
            320x160 is reported as ``image_size``).
        progress: show a tqdm progress bar (stderr) while verifying images.

    Raises:
        FileNotFoundError: if the CSV itself is missing.
        DrivingLogError: if the file is not a log at all (UTF-16, an image, binary data, over
            :data:`MAX_LOG_BYTES` or :data:`MAX_LOG_ROWS`). A bad row is skipped and reported in
            ``DrivingLog.skipped``, never raised.
    """
    if verify_images not in VERIFY_MODES:
        raise ValueError(
            f"verify_images={verify_images!r}; expected one of {', '.join(VERIFY_MODES)}"
        )
    csv_path = resolve_csv_path(path)
    if not csv_path.is_file():
        raise FileNotFoundError(
            f"no driving log at {csv_path}: expected a folder holding {CSV_NAME} and "
            f"{IMAGE_FOLDER}/, or the path of the CSV file"
        )
    folder = csv_path.parent
    image_folder = folder / IMAGE_FOLDER
    raw = _read_log_bytes(csv_path)
    _check_line_count(csv_path, raw)
    warnings: list[str] = []
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        text = raw.decode("utf-8-sig", errors="replace")
        warnings.append(
            f"{csv_path}: not UTF-8 (first bad byte at offset {error.start}); "
            "undecodable bytes were replaced with U+FFFD"
        )

    rows: list[LogRow] = []
    skipped: list[SkippedRow] = []
    has_header = False
    seen_data = False
    for line_number, line in _lines(text):
        fields = line.split(",")
        if len(fields) >= 4 and fields[3].strip().lower() == "steering":
            if not seen_data and not has_header:
                has_header = True
            else:
                warnings.append(f"{csv_path}: line {line_number}: repeated header ignored")
            continue
        seen_data = seen_data or bool(line.strip())
        parsed = _parse_row(line_number, fields, image_folder)
        (rows if isinstance(parsed, LogRow) else skipped).append(parsed)

    rows = _with_speed_labels(folder, rows, warnings)
    if verify_images != "none":
        rows, bad_images = _verify_images(rows, decode=verify_images == "decode", progress=progress)
        skipped = sorted(skipped + bad_images, key=lambda item: item.row)
    return DrivingLog(
        folder=folder,
        csv_path=csv_path,
        rows=rows,
        skipped=skipped,
        total_rows=len(rows) + len(skipped),
        has_header=has_header,
        warnings=warnings,
    )


def _read_log_bytes(csv_path: Path) -> bytes:
    """The CSV's bytes, after checking that it is small enough and looks like text."""
    size = csv_path.stat().st_size
    if size > MAX_LOG_BYTES:
        raise DrivingLogError(
            f"{csv_path}: {size / (1 << 20):.0f} MiB, larger than the "
            f"{MAX_LOG_BYTES >> 20} MiB a driving log may be; not a log?")
    with open(csv_path, "rb") as handle:
        raw = handle.read(MAX_LOG_BYTES + 1)
    head = raw[:4096]
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or (
            b"\x00" in head and head.count(b"\x00") * 3 > len(head)
            and (head[1:2] == b"\x00" or head[:1] == b"\x00")):
        raise DrivingLogError(
            f"{csv_path}: UTF-16 text detected; a driving log is UTF-8 (or ASCII) text: save "
            "it again as UTF-8")
    for magic, what in _MAGIC:
        if head.startswith(magic):
            raise DrivingLogError(f"{csv_path}: not a CSV file: it is {what}")
    if b"\x00" in head:
        raise DrivingLogError(f"{csv_path}: not a CSV file: binary data (NUL bytes)")
    return raw


def _check_line_count(csv_path: Path, raw: bytes) -> None:
    """Refuse a log of more than :data:`MAX_LOG_ROWS` lines, counted in the raw bytes before
    any row is parsed."""
    lines = count_lines(raw)
    if lines > MAX_LOG_ROWS:
        raise DrivingLogError(
            f"{csv_path}: {lines:,} lines, more than the {MAX_LOG_ROWS:,} rows a driving log "
            "may have (a real recording has tens of thousands); not read")


def _with_speed_labels(folder: Path, rows: list[LogRow], warnings: list[str]) -> list[LogRow]:
    """``rows`` with the expert's target speeds of the sidecar file, if the folder has one."""
    from dataclasses import replace

    from clonedrive.data.speed_labels import read_speed_labels

    labels = read_speed_labels(folder)
    if labels is None:
        return rows
    warnings.extend(labels.warnings)
    speeds = labels.speeds_mph
    return [replace(row, target_speed_mph=speeds.get(row.center.name)) for row in rows]


def _lines(text: str) -> Iterator[tuple[int, str]]:
    """(1-based line number, line without its ending) for CRLF, LF or lone-CR endings."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    if lines and lines[-1] == "":
        lines.pop()  # the text after the final newline
    yield from enumerate(lines, start=1)


def _parse_row(line_number: int, fields: list[str], image_folder: Path) -> LogRow | SkippedRow:
    """One CSV line's fields -> a LogRow, or the reason it is unusable (images not checked)."""
    if all(not item.strip() for item in fields):
        return SkippedRow(line_number, "empty", f"line {line_number} is blank")
    count = len(fields)
    if count < len(FIELD_NAMES):
        return SkippedRow(
            line_number,
            "field_count",
            f"line {line_number} has {count} fields, expected 7 ({HEADER_LINE})",
        )
    if count > len(FIELD_NAMES):
        tail = [item.strip() for item in fields[3:]]
        if all(NUMBER.fullmatch(item) for item in tail):
            return SkippedRow(
                line_number,
                "field_count",
                f"line {line_number} has {count} fields, expected 7, and the extra ones are "
                f"numbers: {','.join(tail)!r} looks written in a comma-decimal locale "
                "(0,5 for 0.5); record with a '.'-decimal locale or convert the file",
            )
    # Extra trailing columns (spreadsheet leftovers) are ignored when the first seven make a row.
    parsed = _parse_fields(fields[: len(FIELD_NAMES)], image_folder)
    if isinstance(parsed, tuple):
        reason, problem = parsed
        if count == len(FIELD_NAMES) or reason != "non_numeric":
            return SkippedRow(line_number, reason, f"line {line_number}: {problem}")
        hint = (" (a comma inside an image path?)"
                if any(_looks_like_path(item) for item in fields[3:7]) else "")
        return SkippedRow(
            line_number,
            "field_count",
            f"line {line_number} has {count} fields, expected 7, and its first seven are not a "
            f"row: {problem}{hint}",
        )
    return replace(parsed, row=line_number)


def _parse_fields(fields: list[str], image_folder: Path) -> LogRow | tuple[str, str]:
    """Seven fields -> a LogRow (line number 0), or (reason, what is wrong)."""
    values: list[float] = []
    for name, index, low, high in FIELD_RANGES:
        text = fields[index].strip()
        if _NON_FINITE.fullmatch(text):
            return "non_numeric", f"{name} is {_shown(text)}, expected a finite number"
        if not NUMBER.fullmatch(text):
            return "non_numeric", f"{name} is {_shown(text)}, expected a number"
        value = float(text)
        if not math.isfinite(value):  # e.g. 1e400
            return "non_numeric", f"{name} is {_shown(text)}, too large to be a finite number"
        if (low is not None and value < low - RANGE_TOLERANCE) or (
            high is not None and value > high + RANGE_TOLERANCE
        ):
            expected = f"[{low:g}, {high:g}]" if high is not None else f">= {low:g}"
            return "out_of_range", f"{name} is {value:g}, expected {expected}"
        value = max(value, low) if low is not None else value
        value = min(value, high) if high is not None else value
        values.append(value + 0.0)  # + 0.0 turns -0.0 into 0.0

    paths: list[Path] = []
    for camera, recorded in zip(CAMERAS, fields[:3], strict=True):
        basename = image_basename(recorded)
        if not basename:
            return ("image_missing",
                    f"the {camera} image path {_shown(recorded.strip())} names no file")
        size = len(basename.encode("utf-8", "surrogatepass"))
        if size > MAX_NAME_BYTES:
            return ("image_name", f"the {camera} image name {_shown(basename)} is {size} bytes; "
                                  f"file systems allow {MAX_NAME_BYTES}")
        paths.append(image_folder / basename)
    steering, throttle, brake, speed_mph = values
    return LogRow(0, *paths, steering, throttle, brake, speed_mph)


def _looks_like_path(text: str) -> bool:
    text = text.strip()
    return "/" in text or "\\" in text or text.lower().endswith((".jpg", ".jpeg", ".png"))


def _shown(text: str, limit: int = 60) -> str:
    """``repr(text)``, shortened to about ``limit`` characters."""
    return repr(text) if len(text) <= limit else repr(text[: limit - 3] + "...")


def _verify_images(
    rows: list[LogRow], *, decode: bool, progress: bool
) -> tuple[list[LogRow], list[SkippedRow]]:
    """Split rows into those whose three images are fine and those skipped for an image."""

    def check(row: LogRow) -> LogRow | SkippedRow:
        """The row (with the cameras whose images exist) or why it is skipped."""
        present = []
        for camera in CAMERAS:
            image_path = row.image(camera)
            try:
                exists = image_path.is_file()
            except OSError as error:  # e.g. a folder that cannot be read
                return SkippedRow(
                    row.row,
                    "image_missing",
                    f"line {row.row}: {camera} image {image_path} cannot be read "
                    f"({error.strerror})",
                )
            if exists:
                present.append(camera)
            elif camera == "center":
                return SkippedRow(
                    row.row,
                    "image_missing",
                    f"line {row.row}: {camera} image {image_path} does not exist",
                )
        if decode:
            for camera in present:
                found = decode_problem(row, camera)
                if found is not None:
                    return found
        return row if len(present) == len(CAMERAS) else replace(row, cameras=tuple(present))

    def decode_problem(row: LogRow, camera: str) -> SkippedRow | None:
        image_path = row.image(camera)
        data = image_path.read_bytes()
        if data.startswith(b"\xff\xd8") and not data.rstrip(b"\x00").endswith(b"\xff\xd9"):
            return SkippedRow(
                row.row,
                "image_corrupt",
                f"line {row.row}: {camera} image {image_path} is a truncated JPEG "
                "(no end-of-image marker)",
            )
        try:
            decode_rgb(data, name=str(image_path), shape=IMAGE_SHAPE)
        except ImageDecodeError as error:
            return SkippedRow(row.row, error.reason, f"line {row.row}: {camera} image {error}")
        return None

    iterable = rows
    if progress:
        from clonedrive.base.progress import progress_bar

        iterable = progress_bar(rows, desc="checking images", unit="row", leave=False)
    good: list[LogRow] = []
    bad: list[SkippedRow] = []
    for row in iterable:
        found = check(row)
        (good if isinstance(found, LogRow) else bad).append(found)
    return good, bad
