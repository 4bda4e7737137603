"""``clonedrive check``: the figures it reports for real and broken logs."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from clonedrive.cli import main

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"


def _check_json(capsys: pytest.CaptureFixture[str], *args: str) -> dict:
    assert main(["check", *args, "--json"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1  # one JSON object on one line
    return json.loads(out)


def test_check_json_on_real_log(capsys: pytest.CaptureFixture[str]) -> None:
    summary = _check_json(capsys, str(FIXTURES / "mountain_windows_paths"))
    assert summary["rows"] == 70
    assert summary["usable_rows"] == 70
    assert summary["skipped"] == {}
    assert summary["skipped_rows"] == {}
    assert summary["images_missing"] == 0
    assert summary["images_corrupt"] == 0
    # first center image 09:57:51.708, last 09:57:59.374
    assert summary["duration_s"] == pytest.approx(7.666)
    assert -1.0 <= summary["steering_mean"] < 0.0
    assert summary["steering_std"] > 0.0
    assert sum(summary["steering_histogram"]["counts"]) == 70
    assert summary["speed_mean_mph"] > 10.0


def test_check_json_on_stationary_log(capsys: pytest.CaptureFixture[str]) -> None:
    summary = _check_json(capsys, str(FIXTURES / "stationary"))
    assert summary["rows"] == summary["usable_rows"] == 10
    assert summary["steering_mean"] == 0.0 and summary["steering_std"] == 0.0
    assert summary["speed_mean_mph"] < 1e-4


@pytest.fixture()
def broken_log(tmp_path: Path) -> Path:
    """The stationary recording with a missing image, a corrupt image and two bad rows."""
    folder = tmp_path / "run"
    shutil.copytree(FIXTURES / "stationary", folder)
    lines = (folder / "driving_log.csv").read_text().splitlines(keepends=True)
    first_center = lines[1].split(",")[0].split("\\")[-1]  # row 2's center image
    (folder / "IMG" / first_center).unlink()
    third_left = lines[2].split(",")[1].strip().split("\\")[-1]  # row 3's left image
    (folder / "IMG" / third_left).write_bytes(b"\xff\xd8 not really a jpeg \xff\xd9")
    lines[4] = lines[4].replace(" 0, 0, 0,", " 0,5, 0, 0,")  # row 5: comma-decimal
    lines[6] = lines[6].replace(" 0, 0, 0,", " 2, 0, 0,")  # row 7: steering out of range
    (folder / "driving_log.csv").write_text("".join(lines))
    return folder


def test_check_json_reports_skipped_rows(
    broken_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    summary = _check_json(capsys, str(broken_log))
    assert summary["rows"] == 10
    assert summary["usable_rows"] == 6
    assert summary["skipped"] == {
        "image_missing": 1,
        "image_corrupt": 1,
        "field_count": 1,
        "out_of_range": 1,
    }
    assert summary["skipped_rows"] == {
        "image_missing": [2],
        "image_corrupt": [3],
        "field_count": [5],
        "out_of_range": [7],
    }
    assert summary["images_missing"] == 1
    assert summary["images_corrupt"] == 1

    no_decode = _check_json(capsys, str(broken_log), "--no-decode")
    assert no_decode["usable_rows"] == 7
    assert "image_corrupt" not in no_decode["skipped"]


def test_check_text_report(broken_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(broken_log)]) == 0
    out = capsys.readouterr().out
    assert "rows: 10" in out and "usable: 6" in out
    assert "field_count: 1 (lines 5)" in out
    assert "comma-decimal" in out
    assert "image_missing: 1 (lines 2)" in out
    histogram = [line for line in out.splitlines() if line.strip().startswith("[")]
    assert len(histogram) == 11
    assert histogram[5].rstrip().endswith("######## 6")  # all steering 0: the middle bin
    assert "duration:" in out and "speed: mean" in out


def test_check_lists_first_rows_of_a_large_group(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "IMG").mkdir()
    image = np.zeros((160, 320, 3), np.uint8)
    for camera in ("center", "left", "right"):
        assert cv2.imwrite(str(tmp_path / "IMG" / f"{camera}_a.jpg"), image)
    good = "IMG/center_a.jpg,IMG/left_a.jpg,IMG/right_a.jpg,0.1,0.2,0,5\n"
    bad = "IMG/center_a.jpg,IMG/left_a.jpg,IMG/right_a.jpg,x,0.2,0,5\n"
    (tmp_path / "driving_log.csv").write_text(good + bad * 8)
    assert main(["check", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "non_numeric: 8 (lines 2, 3, 4, 5, 6 and 3 more)" in out
    summary = _check_json(capsys, str(tmp_path))
    assert summary["skipped_rows"]["non_numeric"] == list(range(2, 10))
    assert summary["duration_s"] is None  # names without timestamps


def test_check_missing_csv_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(tmp_path / "nowhere")]) == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "no driving log" in captured.err and "driving_log.csv" in captured.err
