"""The Udacity log reader/writer against real recordings and every kind of bad row."""

from __future__ import annotations

import os
from datetime import datetime
from pathlib import Path

import cv2
import numpy as np
import pytest

from clonedrive.data.driving_log import (
    CAMERAS,
    LogRow,
    image_name,
    image_time,
    read_driving_log,
)
from clonedrive.data.log_writer import DrivingLogWriter

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"


# --- real recordings -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "count"),
    [("lake_posix_mixed_columns", 70), ("mountain_windows_paths", 70), ("stationary", 10)],
)
def test_real_logs_read_completely_with_decoded_images(name: str, count: int) -> None:
    log = read_driving_log(FIXTURES / name, verify_images="decode")
    assert log.skipped == []
    assert len(log.rows) == count
    assert log.total_rows == count
    assert not log.has_header
    assert log.warnings == []
    assert [row.row for row in log.rows] == list(range(1, count + 1))
    for row in log.rows:
        for camera in CAMERAS:
            path = row.image(camera)
            assert path.parent == FIXTURES / name / "IMG"
            assert path.name.startswith(f"{camera}_")
            assert path.is_file()


def test_lake_posix_paths_and_spreadsheet_columns() -> None:
    log = read_driving_log(FIXTURES / "lake_posix_mixed_columns")  # csv file or folder
    folder = FIXTURES / "lake_posix_mixed_columns"
    first = log.rows[0]
    assert first == LogRow(
        row=1,
        center=folder / "IMG" / "center_2018_11_08_17_48_38_718.jpg",
        left=folder / "IMG" / "left_2018_11_08_17_48_38_718.jpg",
        right=folder / "IMG" / "right_2018_11_08_17_48_38_718.jpg",
        steering=0.0,
        throttle=0.0,
        brake=0.0,
        speed_mph=2.471481,
    )
    row39 = log.rows[38]  # a 13-field CRLF row
    assert row39.row == 39
    assert row39.steering == pytest.approx(-0.1320755)
    assert row39.throttle == pytest.approx(0.05458832)
    assert row39.speed_mph == pytest.approx(2.657649)
    last = log.rows[-1]  # a 7-field LF row
    assert last.steering == pytest.approx(-0.3018868)
    assert last.speed_mph == pytest.approx(3.058188)


def test_mountain_windows_paths_leading_spaces() -> None:
    folder = FIXTURES / "mountain_windows_paths"
    log = read_driving_log(folder / "driving_log.csv")
    first = log.rows[0]
    assert first.center == folder / "IMG" / "center_2024_11_21_09_57_51_708.jpg"
    assert first.right == folder / "IMG" / "right_2024_11_21_09_57_51_708.jpg"
    assert (first.steering, first.throttle, first.brake) == (-1.0, 0.0, 0.0)
    assert first.speed_mph == pytest.approx(20.7963)
    last = log.rows[-1]
    assert last.row == 70
    assert last.throttle == pytest.approx(0.4353591)
    assert last.speed_mph == pytest.approx(15.9591)


def test_stationary_exponent_numbers() -> None:
    log = read_driving_log(FIXTURES / "stationary")
    assert log.rows[0].speed_mph == pytest.approx(5.130516e-05)
    assert all(row.steering == 0.0 and row.throttle == 0.0 for row in log.rows)


def test_missing_csv_raises_clear_error(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="driving_log.csv"):
        read_driving_log(tmp_path)


# --- a synthetic log with every kind of bad row ----------------------------------------------


def _write_jpeg(path: Path, shape: tuple[int, int, int] = (160, 320, 3), value: int = 90) -> None:
    image = np.full(shape, value, dtype=np.uint8)
    image[:, : shape[1] // 2] = 200
    assert cv2.imwrite(str(path), image)


def _images(folder: Path, stem: str) -> list[str]:
    """Write three good images named <camera>_<stem>.jpg; their names as a log would hold them."""
    names = []
    for camera in CAMERAS:
        name = f"{camera}_{stem}.jpg"
        _write_jpeg(folder / "IMG" / name)
        names.append(name)
    return names


@pytest.fixture()
def bad_log(tmp_path: Path) -> Path:
    (tmp_path / "IMG").mkdir()

    def row(stem: str, numbers: str, prefix: str = "IMG/", sep: str = ", ") -> str:
        names = _images(tmp_path, stem)
        return sep.join(prefix + name for name in names) + sep + numbers

    corrupt = row("corrupt", "0.1, 0, 0, 10")
    (tmp_path / "IMG" / "left_corrupt.jpg").write_bytes(b"this is not a jpeg at all")
    truncated = row("truncated", "0.1, 0, 0, 10")
    center_bytes = (tmp_path / "IMG" / "center_truncated.jpg").read_bytes()
    (tmp_path / "IMG" / "center_truncated.jpg").write_bytes(center_bytes[: len(center_bytes) // 2])
    small = row("small", "0.1, 0, 0, 10")
    _write_jpeg(tmp_path / "IMG" / "right_small.jpg", shape=(66, 200, 3))
    missing = row("missing", "0.1, 0, 0, 10")
    (tmp_path / "IMG" / "center_missing.jpg").unlink()

    lines = [
        "center,left,right,steering,throttle,brake,speed\n",  # 1 header
        row("good1", "-0.25, 0.5, 0, 20.5", prefix="C:\\Users\\me\\data\\IMG\\") + "\n",  # 2
        row("comma", "-0,5, 0,3, 0, 12,5") + "\n",  # 3 comma-decimal locale
        row("text", "left, 0, 0, 10") + "\n",  # 4 non-numeric steering
        row("nan", "0.1, NaN, 0, 10") + "\n",  # 5 NaN throttle
        row("range", "1.5, 0, 0, 10") + "\n",  # 6 steering out of range
        missing + "\n",  # 7
        corrupt + "\n",  # 8
        row("extra", "0.75, 1, 0, 30", prefix="/data/x/IMG/", sep=",") + ",,x,IMG,c,jpg,\n",  # 9
        "\n",  # 10 blank
        row("crlf", "4.770404E-05, 0, 0, 3.447378E-06", prefix="C:/d/IMG/") + "\r\n",  # 11
        truncated + "\n",  # 12
        small + "\n",  # 13
        "IMG/center_x.jpg, IMG/left_x.jpg, 0.1, 0, 0\n",  # 14 too few fields
        row("negspeed", "0, 0, 0, -3") + "\n",  # 15 negative speed
        row("inf", "0, inf, 0, 3") + "\n",  # 16 infinite throttle
        row("tolerance", "-1.0000001, 1.0000002, 0, 0") + "\n",  # 17 within tolerance
        row("huge", "0, 0, 0, 1e400") + "\n",  # 18 speed overflows to infinity
        row("brake", "0, 0, 1.2, 5"),  # 19 brake out of range, no final newline
    ]
    (tmp_path / "driving_log.csv").write_bytes("".join(lines).encode("utf-8"))
    return tmp_path


EXPECTED_SKIPS = {
    3: "field_count",
    4: "non_numeric",
    5: "non_numeric",
    6: "out_of_range",
    7: "image_missing",
    8: "image_corrupt",
    10: "empty",
    12: "image_corrupt",
    13: "image_size",
    14: "field_count",
    15: "out_of_range",
    16: "non_numeric",
    18: "non_numeric",
    19: "out_of_range",
}


def test_bad_rows_are_skipped_with_reasons_and_line_numbers(bad_log: Path) -> None:
    log = read_driving_log(bad_log, verify_images="decode")
    assert log.has_header
    assert {item.row: item.reason for item in log.skipped} == EXPECTED_SKIPS
    assert [row.row for row in log.rows] == [2, 9, 11, 17]
    assert log.total_rows == 18
    details = {item.row: item.detail for item in log.skipped}
    assert "comma-decimal" in details[3]
    assert "steering" in details[4] and "'left'" in details[4]
    assert "throttle" in details[5]
    assert "steering" in details[6] and "1.5" in details[6]
    assert "center_missing.jpg" in details[7]
    assert "left_corrupt.jpg" in details[8]
    assert "center_truncated.jpg" in details[12]
    assert "200x66" in details[13]
    assert "5 fields" in details[14]
    assert "speed" in details[15]
    assert "finite" in details[18]
    assert "brake" in details[19]

    good, extra, crlf, tolerance = log.rows
    assert good.center == bad_log / "IMG" / "center_good1.jpg"
    assert (good.steering, good.throttle, good.brake, good.speed_mph) == (-0.25, 0.5, 0.0, 20.5)
    assert extra.left == bad_log / "IMG" / "left_extra.jpg"
    assert (extra.steering, extra.throttle, extra.speed_mph) == (0.75, 1.0, 30.0)
    assert crlf.right == bad_log / "IMG" / "right_crlf.jpg"
    assert crlf.steering == pytest.approx(4.770404e-05)
    assert crlf.speed_mph == pytest.approx(3.447378e-06)
    assert (tolerance.steering, tolerance.throttle) == (-1.0, 1.0)  # clamped


def test_verify_modes(bad_log: Path) -> None:
    exists = read_driving_log(bad_log, verify_images="exists")
    assert {item.row: item.reason for item in exists.skipped} == {
        row: reason
        for row, reason in EXPECTED_SKIPS.items()
        if reason not in ("image_corrupt", "image_size")
    }
    trusting = read_driving_log(bad_log, verify_images="none")
    assert 7 in [row.row for row in trusting.rows]
    with pytest.raises(ValueError, match="verify_images"):
        read_driving_log(bad_log, verify_images="maybe")


def test_non_utf8_file_is_read_and_reported(tmp_path: Path) -> None:
    (tmp_path / "IMG").mkdir()
    names = _images(tmp_path, "a")
    line = ",".join(f"C:\\Users\\Jos\xe9\\IMG\\{name}" for name in names) + ",0.5,0.2,0,9\n"
    (tmp_path / "driving_log.csv").write_bytes(line.encode("latin-1") * 2)
    log = read_driving_log(tmp_path)
    assert [row.row for row in log.rows] == [1, 2]
    assert log.rows[0].center == tmp_path / "IMG" / "center_a.jpg"
    assert len(log.warnings) == 1 and "not UTF-8" in log.warnings[0]


def test_comma_in_folder_name_is_reported_not_crashing(tmp_path: Path) -> None:
    (tmp_path / "IMG").mkdir()
    names = _images(tmp_path, "a")
    line = ",".join(f"/home/me/data, new/IMG/{name}" for name in names) + ",0.5,0.2,0,9\n"
    (tmp_path / "driving_log.csv").write_text(line)
    log = read_driving_log(tmp_path)
    assert log.rows == []
    assert log.skipped[0].reason == "field_count"
    assert "comma inside an image path" in log.skipped[0].detail


# --- image names -----------------------------------------------------------------------------


def test_image_name_and_time() -> None:
    start = datetime(2026, 11, 21, 10, 11, 12)
    assert image_name("center", start, 0.345) == "center_2026_11_21_10_11_12_345.jpg"
    assert image_name("left", start, 61.0) == "left_2026_11_21_10_12_13_000.jpg"
    assert image_name("right", start, 1 / 15) == "right_2026_11_21_10_11_12_066.jpg"
    assert image_time("C:\\x\\IMG\\center_2026_11_21_10_11_12_345.jpg") == datetime(
        2026, 11, 21, 10, 11, 12, 345000
    )
    assert image_time("frame_0001.jpg") is None
    with pytest.raises(ValueError, match="camera"):
        image_name("rear", start, 0.0)


# --- writer ----------------------------------------------------------------------------------


def _record(folder: Path, count: int, **writer_options: object) -> list[tuple]:
    """Write ``count`` rows with real JPEGs; the (paths, values) written."""
    rng = np.random.default_rng(7)
    start = datetime(2026, 1, 2, 3, 4, 5)
    written = []
    with DrivingLogWriter(folder, **writer_options) as writer:
        for index in range(count):
            paths = []
            for camera in CAMERAS:
                path = folder / "IMG" / image_name(camera, start, index / 15)
                _write_jpeg(path, value=int(rng.integers(0, 255)))
                paths.append(path)
            values = (
                float(rng.uniform(-1, 1)),
                float(rng.uniform(0, 1)),
                0.0 if index % 2 else float(rng.uniform(0, 1)),
                float(rng.uniform(0, 30)),
            )
            writer.append(*paths, *values)
            written.append((paths, values))
        assert writer.rows_written == count
    return written


def _assert_round_trip(folder: Path, written: list[tuple], first_row: int = 1) -> None:
    log = read_driving_log(folder, verify_images="decode")
    assert log.skipped == []
    assert len(log.rows) == len(written)
    for offset, (row, (paths, values)) in enumerate(zip(log.rows, written, strict=True)):
        assert row.row == first_row + offset
        assert [row.center, row.left, row.right] == paths
        got = (row.steering, row.throttle, row.brake, row.speed_mph)
        assert got == pytest.approx(values, rel=1e-6, abs=1e-9)


def test_writer_round_trip_absolute_paths(tmp_path: Path) -> None:
    written = _record(tmp_path, 6)
    text = (tmp_path / "driving_log.csv").read_text()
    lines = text.splitlines()
    assert len(lines) == 6 and text.endswith("\n")
    assert all(len(line.split(",")) == 7 for line in lines)
    assert lines[0].split(",")[0] == str(tmp_path / "IMG" / "center_2026_01_02_03_04_05_000.jpg")
    assert '"' not in text
    _assert_round_trip(tmp_path, written)


def test_writer_relative_paths_and_header(tmp_path: Path) -> None:
    written = _record(tmp_path, 3, relative_paths=True, header=True)
    more = _record(tmp_path, 2, relative_paths=True, header=True)  # no second header
    lines = (tmp_path / "driving_log.csv").read_text().splitlines()
    assert lines[0] == "center,left,right,steering,throttle,brake,speed"
    assert lines[1].startswith("IMG/center_2026_01_02_03_04_05_000.jpg,IMG/left_")
    assert sum(line.startswith("center,") for line in lines) == 1
    log = read_driving_log(tmp_path)
    assert log.has_header and len(log.rows) == 5
    # the recorded images of the second pass overwrote the first (same names): compare paths only
    assert [row.center for row in log.rows] == [paths[0] for paths, _ in written + more]


def test_writer_append_false_starts_new_log(tmp_path: Path) -> None:
    _record(tmp_path, 4)
    written = _record(tmp_path, 2, append=False)
    _assert_round_trip(tmp_path, written)


def test_writer_number_format(tmp_path: Path) -> None:
    (tmp_path / "IMG").mkdir()
    with DrivingLogWriter(tmp_path, relative_paths=True, fsync=False) as writer:
        writer.append(Path("c.jpg"), Path("l.jpg"), Path("r.jpg"), -0.0, 1, 0, 4.770404e-05)
    line = (tmp_path / "driving_log.csv").read_text()
    assert line == "IMG/c.jpg,IMG/l.jpg,IMG/r.jpg,0,1,0,4.770404e-05\n"


def test_writer_rejects_values_the_reader_would_skip(tmp_path: Path) -> None:
    paths = [tmp_path / "IMG" / f"{camera}_a.jpg" for camera in CAMERAS]
    with DrivingLogWriter(tmp_path) as writer:
        with pytest.raises(ValueError, match="steering"):
            writer.append(*paths, float("nan"), 0, 0, 1)
        with pytest.raises(ValueError, match="throttle"):
            writer.append(*paths, 0, -0.5, 0, 1)
        with pytest.raises(ValueError, match="comma"):
            writer.append(tmp_path / "IMG" / "a,b.jpg", *paths[1:], 0, 0, 0, 1)
        assert writer.rows_written == 0
    with pytest.raises(ValueError, match="closed"):
        writer.append(*paths, 0, 0, 0, 1)
    assert (tmp_path / "driving_log.csv").read_bytes() == b""


def test_killed_writer_leaves_readable_log_and_append_continues(tmp_path: Path) -> None:
    written = _record(tmp_path, 3)
    csv_path = tmp_path / "driving_log.csv"
    data = csv_path.read_bytes()
    third_line_start = data.index(b"\n", data.index(b"\n") + 1) + 1
    cut = third_line_start + 25  # killed while writing row 3's center path
    os.truncate(csv_path, cut)

    log = read_driving_log(tmp_path)  # readable: two rows, the torn one reported
    assert [row.row for row in log.rows] == [1, 2]
    assert [(item.row, item.reason) for item in log.skipped] == [(3, "field_count")]

    with DrivingLogWriter(tmp_path) as writer:
        assert writer.repaired_tail == "truncated"
        writer.append(*written[2][0], *written[2][1])
    _assert_round_trip(tmp_path, written)


def test_append_terminates_a_whole_last_line_without_newline(tmp_path: Path) -> None:
    written = _record(tmp_path, 2)
    csv_path = tmp_path / "driving_log.csv"
    csv_path.write_bytes(csv_path.read_bytes().rstrip(b"\n"))
    more = _record(tmp_path, 1)
    _assert_round_trip(tmp_path, written + more)


def test_append_to_a_crlf_log_keeps_every_row(tmp_path: Path) -> None:
    written = _record(tmp_path, 2)
    csv_path = tmp_path / "driving_log.csv"
    csv_path.write_bytes(csv_path.read_bytes().replace(b"\n", b"\r\n")[:-1])  # torn after \r
    more = _record(tmp_path, 1)
    _assert_round_trip(tmp_path, written + more)
