"""The expert's target speed: recorded in the target_speed.csv sidecar, read back with the log,
and the recorded speed standing in for logs that have none (human and Udacity recordings)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from clonedrive.data.driving_log import read_driving_log
from clonedrive.data.recipe import default_recipe_for, expand
from clonedrive.data.recorder import RecordConfig, record
from clonedrive.data.speed_labels import (
    LABELS_HEADER,
    LABELS_NAME,
    SpeedLabelWriter,
    read_speed_labels,
)
from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy
from clonedrive.sim.simulator import SimConfig, Simulator

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"


def test_recorder_writes_the_expert_target_speed_beside_a_seven_field_log(tmp_path) -> None:
    out = tmp_path / "run"
    record(RecordConfig(track="mountain", seconds=2.0, speed_mph=15.0, scenery=False,
                        start_time="2026-11-21T10:11:12.345"), out, progress=False)
    lines = (out / "driving_log.csv").read_text().splitlines()
    assert {len(line.split(",")) for line in lines} == {7}  # Udacity's format, untouched
    sidecar = (out / LABELS_NAME).read_text().splitlines()
    assert sidecar[0] == LABELS_HEADER and len(sidecar) == len(lines) + 1
    log = read_driving_log(out)
    assert len(log.rows) == 30 and not log.warnings
    speeds = [row.target_speed_mph for row in log.rows]
    # The label is the expert's uncapped target: on the straight start the car's top speed,
    # above the 15 mph set speed, while the recorded speed is what the car did.
    assert all(speed is not None for speed in speeds)
    assert max(speeds) == pytest.approx(30.0, abs=0.01)
    assert max(row.speed_mph for row in log.rows) <= 15.5


def test_label_speed_is_the_profile_without_the_set_speed_cap() -> None:
    with Simulator("mountain", SimConfig(cameras=())) as sim:
        obs, _ = sim.reset(seed=0)
        slow = ExpertPolicy(sim.track, ExpertConfig(speed_mph=10.0))
        fast = ExpertPolicy(sim.track, ExpertConfig(speed_mph=30.0))
        labels_slow, labels_fast, targets_slow = [], [], []
        for _ in range(400):
            action = fast.act(obs)
            labels_fast.append(action.label_speed_mph)
            slow_action = slow.act(obs)
            labels_slow.append(slow_action.label_speed_mph)
            targets_slow.append(slow_action.target_speed_mph)
            obs, _ = sim.step(action.controls_applied)
    # Same state, same label whatever the set speed; the target itself is capped.
    np.testing.assert_allclose(labels_slow, labels_fast)
    assert max(targets_slow) <= 10.0 + 1e-9
    assert min(labels_fast) < 26.0 < max(labels_fast)  # it slows for the mountain's bends


def test_udacity_logs_fall_back_to_the_recorded_speed(tmp_path) -> None:
    folder = tmp_path / "udacity"
    shutil.copytree(FIXTURES / "lake_posix_mixed_columns", folder)
    samples = expand(default_recipe_for([folder]))
    log = read_driving_log(folder)
    assert all(row.target_speed_mph is None for row in log.rows)
    assert samples.rows_with_target_speed == 0
    by_row = {row.row: row.speed_mph for row in log.rows}
    np.testing.assert_allclose(samples.target_speed_mph,
                               [by_row[int(row)] for row in samples.row], rtol=1e-6)


def test_partial_and_bad_sidecars_fall_back_row_by_row(tmp_path) -> None:
    folder = tmp_path / "udacity"
    shutil.copytree(FIXTURES / "lake_posix_mixed_columns", folder)
    rows = read_driving_log(folder).rows
    (folder / LABELS_NAME).write_text(
        f"{LABELS_HEADER}\n{rows[0].center.name},12.5\n{rows[1].center.name},fast\n"
        f"{rows[2].center.name},-3\nnonsense\n{rows[3].center.name},7.25\n", encoding="utf-8")
    log = read_driving_log(folder)
    assert [row.target_speed_mph for row in log.rows[:5]] == [12.5, None, None, 7.25, None]
    assert any("3 line(s)" in warning for warning in log.warnings)
    samples = expand(default_recipe_for([folder]))
    assert samples.rows_with_target_speed == 2
    first = samples.target_speed_mph[samples.row == log.rows[0].row]
    second = samples.target_speed_mph[samples.row == log.rows[1].row]
    assert set(first.tolist()) == {12.5}
    np.testing.assert_allclose(second, log.rows[1].speed_mph, rtol=1e-6)


def test_writer_appends_after_a_torn_line_and_refuses_bad_values(tmp_path) -> None:
    writer = SpeedLabelWriter(tmp_path)
    writer.append("center_a.jpg", 10.0)
    writer.close()
    with open(tmp_path / LABELS_NAME, "a", encoding="utf-8") as handle:
        handle.write("center_b.jp")  # a write torn by a kill
    writer = SpeedLabelWriter(tmp_path)
    writer.append("center_c.jpg", 20.0)
    with pytest.raises(ValueError, match="finite"):
        writer.append("center_d.jpg", float("nan"))
    with pytest.raises(ValueError, match="comma"):
        writer.append("a,b.jpg", 1.0)
    writer.close()
    labels = read_speed_labels(tmp_path)
    assert labels.speeds_mph == {"center_a.jpg": 10.0, "center_c.jpg": 20.0}
    assert labels.skipped_lines == 1
    assert read_speed_labels(tmp_path / "nothing") is None
