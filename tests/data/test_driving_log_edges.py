"""The log reader at its edges: center-only data sets, spreadsheet tails, files that are not logs,
names no file system allows, and images that several rows name."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from clonedrive.cli import main
from clonedrive.data.driving_log import (
    MAX_LOG_BYTES,
    DrivingLogError,
    read_driving_log,
)
from clonedrive.data.recipe import default_recipe_for, expand

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"
LAKE = FIXTURES / "lake_posix_mixed_columns"  # 40 rows of 13 fields (CRLF), then 30 of 7 (LF)


@pytest.fixture()
def center_only(tmp_path: Path) -> Path:
    """The lake slice as people share it: every CSV line kept, only the center images."""
    folder = tmp_path / "center_only"
    (folder / "IMG").mkdir(parents=True)
    for image in (LAKE / "IMG").glob("center_*.jpg"):
        shutil.copy(image, folder / "IMG" / image.name)
    lines = (LAKE / "driving_log.csv").read_bytes().splitlines(keepends=True)
    # Line 3124 of the full recording: its spreadsheet tail holds a number ('7').
    assert lines[20].endswith(b",jpg,\r\n")
    lines[20] = lines[20][: -len(b",jpg,\r\n")] + b",21_943,7\r\n"
    (folder / "driving_log.csv").write_bytes(b"".join(lines))
    return folder


def test_a_center_only_log_is_usable_for_the_center_camera(center_only: Path) -> None:
    log = read_driving_log(center_only, verify_images="decode")
    assert len(log.rows) == log.total_rows == 70 and not log.skipped
    assert log.side_images_missing == 70
    assert all(row.cameras == ("center",) for row in log.rows)
    samples = expand(default_recipe_for([center_only]))  # cameras = "all" by default
    assert samples.skipped == {} and samples.side_images_missing == 70
    assert set(samples.camera.tolist()) == {0}  # center only
    assert len(samples) == 70 * 2  # each center image and its mirror


def test_check_reports_center_only_rows(center_only: Path, capsys) -> None:
    assert main(["check", str(center_only)]) == 0
    printed = capsys.readouterr().out
    assert "rows: 70   usable: 70   skipped: 0" in printed
    assert "70 have no left and/or right image" in printed


def test_a_missing_center_image_still_skips_the_row(center_only: Path) -> None:
    first = read_driving_log(center_only).rows[0]
    first.center.unlink()
    log = read_driving_log(center_only)
    assert [(item.row, item.reason) for item in log.skipped] == [(1, "image_missing")]
    assert "center image" in log.skipped[0].detail


def test_extra_fields_after_seven_valid_ones_are_ignored_and_bad_ones_named(
        tmp_path: Path) -> None:
    (tmp_path / "IMG").mkdir()
    for camera in ("center", "left", "right"):
        source = next((LAKE / "IMG").glob(f"{camera}_*.jpg"))
        shutil.copy(source, tmp_path / "IMG" / f"{camera}.jpg")
    paths = "/d/IMG/center.jpg,/d/IMG/left.jpg,/d/IMG/right.jpg"
    (tmp_path / "driving_log.csv").write_text(
        f"{paths},-0.1792453,0,0,3.12263,,Data,IMG,center_x,21_943,7\n"  # 1: numbers in the tail
        f"{paths},left,0,0,3.1,,Data,IMG,center_x,jpg,\n"  # 2: steering is not a number
        "/a,b/IMG/center.jpg,/a,b/IMG/left.jpg,/a,b/IMG/right.jpg,0,0,0,1\n")  # 3: comma in path
    log = read_driving_log(tmp_path)
    assert [row.row for row in log.rows] == [1]
    assert log.rows[0].steering == pytest.approx(-0.1792453)
    details = {item.row: item.detail for item in log.skipped}
    assert "13 fields" in details[2] and "steering is 'left'" in details[2]
    assert "fields 4-7" not in details[2] and "comma inside an image path" not in details[2]
    assert "comma inside an image path" in details[3]


@pytest.mark.parametrize("content, expected", [
    ("a,b,c,0,0,0,1\n".encode("utf-16"), "UTF-16 text detected"),
    ("a,b,c,0,0,0,1\n".encode("utf-16-le"), "UTF-16 text detected"),
    (b"\xff\xd8\xff\xe0\x00\x10JFIF" + bytes(2000), "not a CSV file: it is a JPEG image"),
    (b"PK\x03\x04" + bytes(100), "not a CSV file: it is a zip file"),
    (b"abc\x00def\n" * 10, "binary data"),
])
def test_files_that_are_not_logs_are_named(tmp_path: Path, capsys, content, expected) -> None:
    (tmp_path / "driving_log.csv").write_bytes(content)
    with pytest.raises(DrivingLogError, match=expected):
        read_driving_log(tmp_path)
    assert main(["check", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1


def test_log_size_is_capped_before_reading(tmp_path: Path) -> None:
    with open(tmp_path / "driving_log.csv", "wb") as handle:
        handle.truncate(MAX_LOG_BYTES + 1)  # sparse: nothing is written or read
    with pytest.raises(DrivingLogError, match=f"larger than the {MAX_LOG_BYTES >> 20} MiB"):
        read_driving_log(tmp_path)


@pytest.mark.parametrize("verify", ["exists", "decode"])
def test_a_name_longer_than_a_file_system_allows_skips_one_row(center_only: Path,
                                                                verify: str) -> None:
    csv = center_only / "driving_log.csv"
    lines = csv.read_text().splitlines(keepends=True)
    lines[2] = "/d/IMG/" + "c" * 300 + ".jpg" + lines[2][lines[2].index(","):]
    csv.write_text("".join(lines))
    log = read_driving_log(center_only, verify_images=verify)
    assert len(log.rows) == 69
    assert [(item.row, item.reason) for item in log.skipped] == [(3, "image_name")]
    assert "304 bytes" in log.skipped[0].detail and "255" in log.skipped[0].detail


def test_check_reports_images_that_several_rows_name(center_only: Path, capsys) -> None:
    csv = center_only / "driving_log.csv"
    lines = csv.read_text().splitlines(keepends=True)
    csv.write_text("".join(lines + lines[60:62]))  # rows 71, 72 repeat 61, 62
    assert main(["check", str(center_only), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["shared_images"] == 2
    assert summary["rows_sharing_images"] == [61, 62, 71, 72]
    assert main(["check", str(center_only)]) == 0
    assert "image files named by more than one row: 2" in capsys.readouterr().out
