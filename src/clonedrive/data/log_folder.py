"""A folder being recorded into: getting it ready for a session and its ``config.json``.

:func:`prepare_log_folder` removes the half-written images a killed recorder left and picks the
first image's time so that new rows follow the last image already logged (image names stay
unique and ordered); :func:`write_session_config` keeps ``config.json``'s list of the sessions
recorded into the folder. Used by ``record`` (:mod:`clonedrive.data.recorder`), manual driving
and DAgger, which write their rows through :class:`~clonedrive.data.row_sink.RowSink`.
"""

from __future__ import annotations

import math
from datetime import datetime, timedelta
from pathlib import Path

from clonedrive.base.config import JsonFileError, config_to_dict, read_json, write_json_atomic
from clonedrive.base.output_files import refuse_link
from clonedrive.data.driving_log import CSV_NAME, IMAGE_FOLDER, image_time, read_driving_log
from clonedrive.data.row_sink import TEMP_SUFFIX
from clonedrive.data.speed_labels import LABELS_NAME

CONFIG_NAME = "config.json"
#: Image names count on from the start in simulated time: a start after this would run past
#: the last date Python can name (9999-12-31) within a recording (a year of driving).
LATEST_START_TIME = datetime(9999, 1, 1)


class RecordingFolderError(RuntimeError):
    """The folder's log cannot be continued (its last image's time leaves no room); one line."""


def prepare_log_folder(out: Path, start_time: str | None = None) -> tuple[int, datetime]:
    """Get ``out`` ready for a new recording session: remove half-written temp images a killed
    recorder left, and choose the first image's time (``start_time``, ISO, or now) so that it
    follows the last image already logged there. Returns (rows already in the log, start).
    A symbolic link at the name of a file the recording reads and writes is refused
    (:class:`~clonedrive.base.output_files.RefusedOutputError`) before anything is written."""
    for name in (CSV_NAME, LABELS_NAME, CONFIG_NAME, IMAGE_FOLDER):
        refuse_link(out / name)
    existing_rows, last_time = _existing_log(out)
    _remove_temp_images(out)
    return existing_rows, _start_time(start_time, last_time)


def _existing_log(out: Path) -> tuple[int, datetime | None]:
    """(rows already in ``out``'s log, the latest image time among them)."""
    if not (out / CSV_NAME).is_file():
        return 0, None
    log = read_driving_log(out, verify_images="none")
    times = [image_time(row.center) for row in log.rows]
    times = [moment for moment in times if moment is not None]
    return log.total_rows, max(times) if times else None


def _start_time(start_time: str | None, last_time: datetime | None) -> datetime:
    """The time of the first image: ``start_time`` or now (whole ms), and in any case after the
    last image already in the folder."""
    if start_time is not None:
        start = datetime.fromisoformat(start_time).replace(tzinfo=None)
    else:
        start = datetime.now()
    start = start.replace(microsecond=start.microsecond // 1000 * 1000)
    if last_time is not None and last_time >= LATEST_START_TIME:
        raise RecordingFolderError(
            f"the log's last image is named for {last_time.isoformat()}: too late to record "
            f"after it (image names must stay before {LATEST_START_TIME.date().isoformat()}); "
            "record into another folder")
    if last_time is not None:
        start = max(start, last_time + timedelta(milliseconds=math.ceil(1000 / 15)))
    return start


def check_start_time(start: datetime) -> None:
    """``ValueError`` unless a recording starting at ``start`` can name its images (see
    :data:`LATEST_START_TIME`)."""
    if start.replace(tzinfo=None) >= LATEST_START_TIME:
        raise ValueError(f"start_time {start.isoformat()} is too late: a recording must start "
                         f"before {LATEST_START_TIME.date().isoformat()} (its image names count "
                         "on from it)")


def _remove_temp_images(out: Path) -> None:
    """Delete ``IMG/.*.tmp.jpg`` files a killed recorder left half-written."""
    folder = out / IMAGE_FOLDER
    if folder.is_dir():
        for temp in folder.glob(f".*{TEMP_SUFFIX}"):
            temp.unlink(missing_ok=True)


def write_session_config(out: Path, config, track, version: str, session: dict) -> None:
    """config.json: this recording's config (a dataclass), the track version, clonedrive version,
    and every session recorded into the folder (``session`` replaces an earlier entry with the
    same ``started``)."""
    path = out / CONFIG_NAME
    sessions: list = []
    if path.is_file():
        try:
            previous = read_json(path, what="config file")
        except JsonFileError:  # unreadable: start the list of sessions afresh
            previous = {}
        if isinstance(previous, dict) and isinstance(previous.get("sessions"), list):
            sessions = [item for item in previous["sessions"]
                        if item.get("started") != session["started"]]
    data = config_to_dict(config)
    data.update(track_name=track.name, track_version=track.version,
                track_length_m=round(track.length_m, 1), clonedrive_version=version,
                sessions=[*sessions, session])
    write_json_atomic(path, data)
