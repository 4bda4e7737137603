"""The recorder writes exactly the Udacity format, appends safely, and loses nothing when killed."""

import json
import os
import signal
import subprocess
import sys
import time
from datetime import datetime, timedelta
from itertools import pairwise

import pytest

from clonedrive.data.driving_log import image_time, read_driving_log
from clonedrive.data.recorder import RecordConfig, record

START = "2026-11-21T10:11:12.345"


def short(**options):
    values = {"track": "lake", "laps": 1, "seconds": 2.0, "speed_mph": 20.0, "start_time": START,
              "scenery": False}
    values.update(options)
    return RecordConfig(**values)


def test_writes_a_udacity_log_that_reads_back_whole(tmp_path):
    out = tmp_path / "run"
    summary = record(short(), out, progress=False)
    assert summary.rows == 30 and summary.stopped == "seconds"
    assert summary.off_road_events == 0 and not summary.appended
    assert sum(summary.steering_histogram["counts"]) == 30

    log = read_driving_log(out, verify_images="decode")  # also checks 320x160x3
    assert len(log.rows) == 30 and not log.skipped and not log.has_header
    first = log.rows[0]
    assert first.center.name == "center_2026_11_21_10_11_12_345.jpg"
    assert first.left.name == "left_2026_11_21_10_11_12_345.jpg"
    assert first.right.name == "right_2026_11_21_10_11_12_345.jpg"
    # Absolute paths, seven fields, no header, as the simulator writes.
    lines = (out / "driving_log.csv").read_text().splitlines()
    assert len(lines) == 30
    fields = lines[0].split(",")
    assert len(fields) == 7 and os.path.isabs(fields[0])
    assert fields[0] == str(out / "IMG" / first.center.name)
    # Names follow simulated time: 1/15 s apart, unique.
    times = [image_time(row.center) for row in log.rows]
    gaps_ms = {round((b - a).total_seconds() * 1000) for a, b in pairwise(times)}
    assert gaps_ms <= {66, 67}
    assert times[-1] - times[0] == timedelta(milliseconds=1933)  # 29/15 s, truncated to ms
    # Values: the car starts at rest and accelerates; labels and controls are in range.
    assert log.rows[0].speed_mph == 0.0 and log.rows[-1].speed_mph > 5.0
    assert all(0.0 <= row.throttle <= 1.0 and 0.0 <= row.brake <= 1.0 for row in log.rows)
    assert all(-1.0 <= row.steering <= 1.0 for row in log.rows)
    # No temporary files are left behind.
    assert sorted(p.name for p in (out / "IMG").iterdir()) == sorted(
        p.name for row in log.rows for p in (row.center, row.left, row.right))

    config = json.loads((out / "config.json").read_text())
    assert config["track"] == "lake" and config["track_version"] == 1
    assert config["style"] == "center" and config["speed_mph"] == 20.0
    assert config["seed"] == 0 and config["laps"] == 1 and config["reverse"] is False
    assert config["noise"] == 0.0 and config["clonedrive_version"]
    assert [session["rows"] for session in config["sessions"]] == [30]


def test_images_are_rgb_as_rendered(tmp_path):
    import cv2
    import numpy as np

    from clonedrive.sim.simulator import SimConfig, Simulator

    record(short(seconds=0.1, jpeg_quality=95), tmp_path, progress=False)
    log = read_driving_log(tmp_path)
    with Simulator("lake", SimConfig(scenery=False)) as sim:
        obs, _ = sim.reset(seed=0)
    for camera in ("center", "left", "right"):
        written = cv2.imread(str(log.rows[0].image(camera)))[:, :, ::-1]  # BGR file -> RGB
        rendered = obs.images[camera].astype(int)
        difference = np.abs(written.astype(int) - rendered).mean()
        swapped = np.abs(written[:, :, ::-1].astype(int) - rendered).mean()
        assert difference < 3.0 and swapped > 3 * difference  # JPEG loss only


def test_header_and_relative_paths(tmp_path):
    record(short(seconds=0.5, header=True, relative_paths=True), tmp_path, progress=False)
    lines = (tmp_path / "driving_log.csv").read_text().splitlines()
    assert lines[0] == "center,left,right,steering,throttle,brake,speed"
    assert lines[1].startswith("IMG/center_2026_11_21_10_11_12_345.jpg,IMG/left_")
    log = read_driving_log(tmp_path, verify_images="decode")
    assert log.has_header and len(log.rows) == 8 and not log.skipped


def test_recording_into_an_existing_folder_appends_after_its_last_image(tmp_path):
    record(short(seconds=1.0), tmp_path, progress=False)
    summary = record(short(seconds=1.0, style="right", seed=4), tmp_path, progress=False)
    assert summary.appended and summary.rows == 15 and summary.total_rows == 30
    log = read_driving_log(tmp_path, verify_images="decode")
    assert len(log.rows) == 30 and not log.skipped
    times = [image_time(row.center) for row in log.rows]
    assert all(b > a for a, b in pairwise(times))  # unique and ordered
    assert times[15] - times[14] <= timedelta(milliseconds=67)
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["style"] == "right"
    assert [(s["style"], s["rows"]) for s in config["sessions"]] == [("center", 15), ("right", 15)]


def test_turns_records_only_the_curved_steps(tmp_path):
    # Driving the lake backwards starts in a curve that straightens after about 50 m.
    summary = record(short(style="turns", reverse=True, seconds=9.0, speed_mph=30.0), tmp_path,
                     progress=False)
    assert summary.rows > 10 and summary.skipped_samples > 10
    assert summary.rows + summary.skipped_samples == 135
    log = read_driving_log(tmp_path, verify_images="decode")
    assert len(log.rows) == summary.rows and not log.skipped


def test_the_wall_clock_start_is_used_without_start_time(tmp_path):
    before = datetime.now() - timedelta(seconds=1)
    record(short(seconds=0.2, start_time=None), tmp_path, progress=False)
    first = image_time(read_driving_log(tmp_path).rows[0].center)
    assert before <= first <= datetime.now()


def test_bad_configs_are_refused():
    with pytest.raises(ValueError, match="style"):
        RecordConfig(style="sideways")
    with pytest.raises(ValueError, match="speed_mph"):
        RecordConfig(speed_mph=45.0)
    with pytest.raises(ValueError):
        RecordConfig(start_time="yesterday")


def test_a_recorder_killed_with_sigkill_leaves_a_whole_log(tmp_path):
    out = tmp_path / "killed"
    code = (
        "import sys\n"
        "from clonedrive.data.recorder import RecordConfig, record\n"
        "record(RecordConfig(track='lake', laps=5, speed_mph=30.0, scenery=False), sys.argv[1],"
        " progress=False)\n"
    )
    csv = out / "driving_log.csv"
    for kill_after_rows in (40, 90):  # two kills into the same folder: it appends each time
        process = subprocess.Popen([sys.executable, "-c", code, str(out)])
        try:
            deadline = time.monotonic() + 120.0
            while time.monotonic() < deadline:
                if csv.is_file() and csv.read_bytes().count(b"\n") >= kill_after_rows:
                    break
                if process.poll() is not None:
                    pytest.fail(f"the recorder exited early with status {process.returncode}")
                time.sleep(0.01)
            else:
                pytest.fail("the recorder wrote too few rows in 120 s")
        finally:
            os.kill(process.pid, signal.SIGKILL)
            process.wait()
        assert process.returncode == -signal.SIGKILL
        log = read_driving_log(out, verify_images="decode")
        assert log.skipped == []
        assert len(log.rows) >= kill_after_rows
        times = [image_time(row.center) for row in log.rows]
        assert all(b > a for a, b in pairwise(times))
