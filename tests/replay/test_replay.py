"""Closed-loop replay on real Udacity frames: the homography, side views synthesised against the
real side cameras, drift and interventions, episodes, refusals and the command."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from clonedrive.base.images import read_rgb
from clonedrive.cli import main
from clonedrive.data.driving_log import read_driving_log
from clonedrive.replay.episode import (
    ReplayConfig,
    ReplayError,
    frame_images,
    frame_times,
    replayable_episodes,
    split_episodes,
)
from clonedrive.replay.output import replay
from clonedrive.replay.view import Rig, calibrate, side_view_errors, source_coordinates, synthesise

FIXTURES = Path(__file__).parents[1] / "fixtures" / "udacity"
LAKE = FIXTURES / "lake_posix_mixed_columns"  # 70 three-camera rows in three time segments, slow
MOUNTAIN = FIXTURES / "mountain_windows_paths"  # 70 consecutive rows, ~17 mph, keyboard steering
STATIONARY = FIXTURES / "stationary"


class TablePolicy:
    """Steers as the human did on each recorded frame, or a constant."""

    def __init__(self, log: Path, constant: float | None = None) -> None:
        self.constant = constant
        self.table = {read_rgb(row.center).tobytes(): row.steering
                      for row in read_driving_log(log).rows}
        self.resets = 0

    def reset(self) -> None:
        self.resets += 1

    def act(self, image: np.ndarray, speed_mph: float) -> tuple[float, float]:
        if self.constant is not None:
            return self.constant, 0.0
        return self.table[image.tobytes()], 0.0


@pytest.fixture(scope="module")
def lake_frames() -> list[dict[str, np.ndarray]]:
    rows = read_driving_log(LAKE).rows
    return [frame_images(row) for row in rows[::7]]


def test_no_move_no_turn_is_the_identity(lake_frames) -> None:
    rig = Rig()
    map_x, map_y = source_coordinates(rig, 0.0, 0.0)
    rows, cols = np.mgrid[0:rig.height, 0:rig.width]
    np.testing.assert_allclose(map_x, cols, atol=1e-3)
    np.testing.assert_allclose(map_y, rows, atol=1e-3)
    frame = lake_frames[0]
    np.testing.assert_array_equal(synthesise(frame, rig, 0.0, 0.0), frame["center"])
    # Through the resampling too: a move too small to shift a pixel changes nothing.
    np.testing.assert_array_equal(synthesise(frame, rig, 1e-9, 0.0), frame["center"])


def test_above_the_horizon_a_move_changes_nothing() -> None:
    rig = Rig()
    still_x, _ = source_coordinates(rig, 0.0, 0.05)
    moved_x, _ = source_coordinates(rig, 0.8, 0.05)
    sky = slice(0, int(rig.horizon_row) - 1)
    np.testing.assert_allclose(moved_x[sky], still_x[sky], atol=1e-3)
    assert np.nanmean(np.abs(moved_x[100] - still_x[100])) > 10  # the road moves a lot


def test_synthesised_side_views_are_closer_to_the_real_ones(lake_frames) -> None:
    rig = Rig()
    for camera in ("left", "right"):
        synthesised, unshifted = side_view_errors(rig, lake_frames, camera)
        assert synthesised < 0.75 * unshifted, camera


def test_calibration_finds_the_side_cameras(lake_frames) -> None:
    start = replace(Rig(), left_x_m=-0.5, right_x_m=0.5, horizon_row=61.5)
    fitted = calibrate(start, lake_frames[:4])
    assert -0.9 <= fitted.left_x_m <= -0.65
    assert 0.65 <= fitted.right_x_m <= 0.9
    assert 58.5 <= fitted.horizon_row <= 60.5


def test_side_images_fill_the_edges(lake_frames) -> None:
    rig = Rig()
    frame = lake_frames[2]
    alone = synthesise({"center": frame["center"]}, rig, 0.7, 0.0)
    filled = synthesise(frame, rig, 0.7, 0.0)
    # The right camera saw the bottom-right corner the centre camera did not.
    corner = (slice(120, 135), slice(300, 320))
    right_view, _ = source_coordinates(rig, 0.7, 0.0, rig.right_x_m)
    assert not np.array_equal(alone[corner], filled[corner])
    assert np.isfinite(right_view[corner]).all()


def test_a_model_equal_to_the_human_needs_no_help(tmp_path: Path) -> None:
    policy = TablePolicy(MOUNTAIN)
    report = replay(policy, [MOUNTAIN], tmp_path)
    figures = report["totals"]
    assert figures["interventions"] == 0 and figures["autonomy_pct"] == 100.0
    assert figures["max_abs_offset_m"] == 0.0
    assert figures["distance_m"] > 40
    assert report["logs"][0]["sources"] == ["center", "left", "right"]
    assert report["logs"][0]["calibrated"]
    assert policy.resets == 1


def test_a_centre_only_log_replays_and_says_so(tmp_path: Path) -> None:
    log = tmp_path / "centre_only"
    shutil.copytree(MOUNTAIN, log, ignore=shutil.ignore_patterns("left_*", "right_*"))
    report = replay(TablePolicy(log, constant=0.1), [log], tmp_path / "out")
    entry = report["logs"][0]
    assert entry["sources"] == ["center"] and not entry["calibrated"]
    assert "centre-only" in entry["edges"] and entry["max_offset_m"] == 1.0
    assert report["totals"]["interventions"] >= 1


def test_a_car_that_never_steers_drifts_off(tmp_path: Path) -> None:
    report = replay(TablePolicy(MOUNTAIN, constant=0.0), [MOUNTAIN], tmp_path)
    figures = report["totals"]
    assert figures["interventions"] >= 1
    assert figures["autonomy_pct"] < 100.0
    assert figures["interventions_per_km"] > 10
    assert figures["jitter_per_s"] == 0.0 < figures["human_jitter_per_s"]


def test_a_jump_in_the_timestamps_starts_a_new_episode() -> None:
    rows = read_driving_log(LAKE).rows
    episodes = split_episodes(rows, frame_times(rows), min_frames=2)
    assert [len(episode.rows) for episode in episodes] == [40, 12, 18]
    assert all(episode.times_s[0] == 0.0 for episode in episodes)
    config = ReplayConfig(min_distance_m=1.0, min_episode_frames=15)
    assert [len(episode.rows) for episode in replayable_episodes(LAKE, config)] == [40, 18]


def test_logs_that_cannot_be_replayed_are_refused(tmp_path: Path) -> None:
    speedless = tmp_path / "speedless"
    shutil.copytree(MOUNTAIN, speedless)
    csv = speedless / "driving_log.csv"
    lines = csv.read_text().splitlines()
    csv.write_text("".join(line.rsplit(",", 1)[0] + ", 0\n" for line in lines))
    with pytest.raises(ReplayError, match="no speed"):
        replayable_episodes(speedless, ReplayConfig())
    with pytest.raises(ReplayError, match="stationary"):
        replayable_episodes(STATIONARY, ReplayConfig())
    with pytest.raises(ReplayError, match="too short"):
        replayable_episodes(MOUNTAIN, ReplayConfig(min_episode_frames=100))


@pytest.mark.slow
def test_the_command(tmp_path: Path, tiny_model_path: Path, capsys) -> None:
    out = tmp_path / "replay"
    assert main(["replay", str(tiny_model_path), str(MOUNTAIN), "--out", str(out),
                 "--video"]) == 0
    report = json.loads((out / "replay.json").read_text())
    assert report["totals"]["frames"] == 70 and (out / "replay.png").stat().st_size > 1000
    assert report["files"]["video"] == "replay.mp4" and (out / "replay.mp4").stat().st_size > 0
    assert "autonomy" in capsys.readouterr().out
    assert report["config"]["vehicle_model"] == "kinematic"
    assert main(["replay", str(tiny_model_path), str(MOUNTAIN), "--out", str(tmp_path / "dyn"),
                 "--vehicle-model", "dynamic"]) == 0
    dynamic = json.loads((tmp_path / "dyn" / "replay.json").read_text())
    assert dynamic["config"]["vehicle_model"] == "dynamic"
    assert dynamic["totals"]["mean_abs_offset_m"] != report["totals"]["mean_abs_offset_m"]
    capsys.readouterr()
    assert main(["replay", str(tiny_model_path), str(STATIONARY), "--out", str(out)]) == 1
    error = capsys.readouterr().err.strip()
    assert error.startswith("clonedrive replay: ") and "stationary" in error
    assert len(error.splitlines()) == 1
    assert main(["replay", str(tiny_model_path), str(MOUNTAIN), "--max-offset", "0"]) == 2
