"""A driving log of millions of short rows is refused from its line count, before any row is
parsed (data.line_count.MAX_LOG_ROWS); one at the limit is read in bounded memory."""

from __future__ import annotations

from pathlib import Path

import pytest
from support.hostile_files import log_of_many_rows
from support.measured import run_measured

from clonedrive.data.driving_log import (
    DrivingLogError,
    read_driving_log,
)
from clonedrive.data.line_count import MAX_LOG_ROWS, count_lines

UDACITY_IMAGES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity" / "stationary" / "IMG"
#: Peak memory a clonedrive process may reach on a log at (or past) the limit [MB].
LOG_PEAK_MB = 2000


def blank_log(folder: Path, lines: int) -> Path:
    """A log of ``lines`` empty lines: small on disk, each a row to the reader."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "driving_log.csv").write_bytes(b"\n" * lines)
    return folder


@pytest.mark.parametrize(("raw", "lines"), [(b"", 0), (b"a", 1), (b"a\n", 1), (b"a\r\nb", 2),
                                            (b"a\rb\r", 2), (b"a\n\nb\n", 3)])
def test_lines_are_counted_as_the_reader_splits_them(raw: bytes, lines: int) -> None:
    assert count_lines(raw) == lines


def test_a_log_past_the_row_limit_is_refused_naming_file_and_limit(tmp_path: Path) -> None:
    folder = blank_log(tmp_path / "long", MAX_LOG_ROWS + 1)
    with pytest.raises(DrivingLogError) as refused:
        read_driving_log(folder, verify_images="none")
    assert str(refused.value) == (
        f"{folder / 'driving_log.csv'}: {MAX_LOG_ROWS + 1:,} lines, more than the "
        f"{MAX_LOG_ROWS:,} rows a driving log may have (a real recording has tens of "
        "thousands); not read")


@pytest.mark.parametrize("verb", [["check", "--no-decode"], ["train", "--epochs", "1"]])
def test_real_processes_refuse_a_log_past_the_limit(verb: list[str], tmp_path: Path) -> None:
    folder = blank_log(tmp_path / "long", MAX_LOG_ROWS + 1)
    argv = [verb[0], folder, *verb[1:]]
    if verb[0] == "train":
        argv += ["--out", tmp_path / "run"]
    finished = run_measured(*argv)
    assert finished.rc == 1
    assert "Traceback" not in finished.stderr
    last = finished.stderr.strip().splitlines()[-1]
    assert last.startswith(f"clonedrive {verb[0]}: ") and f"{MAX_LOG_ROWS:,} rows" in last
    assert finished.peak_rss_mb < LOG_PEAK_MB


@pytest.mark.slow
def test_a_log_at_the_limit_is_read_in_bounded_memory(tmp_path: Path) -> None:
    folder = log_of_many_rows(tmp_path / "long", MAX_LOG_ROWS, UDACITY_IMAGES)
    finished = run_measured("check", folder, "--no-decode", "--json")
    assert finished.rc == 0, finished.stderr
    assert finished.peak_rss_mb < LOG_PEAK_MB


def test_a_speed_label_sidecar_past_the_row_limit_is_not_read(tmp_path: Path) -> None:
    from clonedrive.data.speed_labels import LABELS_NAME, read_speed_labels

    (tmp_path / LABELS_NAME).write_bytes(b"c.jpg,1\n" * (MAX_LOG_ROWS + 2))
    labels = read_speed_labels(tmp_path)
    assert labels is not None and labels.speeds_mph == {}
    assert labels.warnings == [
        f"{tmp_path / LABELS_NAME}: {MAX_LOG_ROWS + 2:,} lines, more than the {MAX_LOG_ROWS:,} "
        "rows a driving log may have; not read (recorded speeds stand in for the expert's "
        "target speed)"]
