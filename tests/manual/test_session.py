"""Manual driving's logic, headless: input events in, controls, modes, recordings and HUD out."""

from __future__ import annotations

import json
from datetime import timedelta

import numpy as np
import pytest

from clonedrive.data.driving_log import image_time, read_driving_log
from clonedrive.manual.config import ManualConfig
from clonedrive.manual.human_input import GAMEPAD, KEYBOARD, MOUSE, move_toward
from clonedrive.manual.session import AUTONOMOUS, DRIVING, MENU, DrivingSession
from clonedrive.sim.simulator import SimConfig

STATE_ONLY = SimConfig(cameras=(), scenery=False)
CAMERAS = SimConfig(scenery=False)
DT_S = 1.0 / 15.0


def open_session(tmp_path, *, sim_config=STATE_ONLY, **config) -> DrivingSession:
    """A session driving the lake track (chosen through the menu with Enter)."""
    session = DrivingSession(ManualConfig(scenery=False, **config), tmp_path / "manual",
                             sim_config=sim_config)
    assert session.mode == MENU
    session.key_down("enter")
    session.key_up("enter")
    assert session.loading
    session.step()  # opens the track
    assert session.mode == DRIVING and session.track_name == "lake"
    return session


def steer_for(session: DrivingSession, steps: int) -> list[float]:
    values = []
    for _ in range(steps):
        session.step()
        values.append(session.controls.steering)
    return values


def test_move_toward_never_overshoots():
    assert move_toward(0.0, 1.0, 0.3) == pytest.approx(0.3)
    assert move_toward(0.9, 1.0, 0.3) == 1.0
    assert move_toward(-0.1, 0.0, 0.3) == 0.0
    assert move_toward(0.5, -1.0, 0.2) == pytest.approx(0.3)


def test_keyboard_steering_ramps_smoothly_and_returns_to_centre(tmp_path):
    config = ManualConfig()
    turn = config.keyboard_steer_rate_per_s * DT_S  # 0.08 per step
    back = config.keyboard_return_rate_per_s * DT_S
    with open_session(tmp_path) as session:
        session.key_down("arrow_left")
        held = steer_for(session, 16)
        session.key_up("arrow_left")
        released = steer_for(session, 12)
        # A ramp, not a -1 spike: the first step turns the wheel by one increment only.
        assert held[0] == pytest.approx(-turn)
        assert np.allclose(np.diff(held[:12]), -turn)
        assert held[-1] == pytest.approx(-1.0)  # full lock after 1/1.2 s
        assert min(held) >= -1.0
        assert np.all(np.diff(released) >= 0)
        assert released[0] == pytest.approx(-1.0 + back)
        assert released[-1] == 0.0  # exactly centred, and it stays there
        steps = np.abs(np.diff([0.0, *held, *released]))
        assert steps.max() <= max(turn, back) + 1e-9
        # D steers right the same way; pressing it while steering left returns at the faster
        # centring rate first.
        session.key_down("a")
        steer_for(session, 5)
        session.key_up("a")
        session.key_down("d")
        right = steer_for(session, 30)
        assert right[0] == pytest.approx(-5 * turn + back)
        assert right[-1] == pytest.approx(1.0)
        assert session.steering_source == KEYBOARD


def test_throttle_keys_ramp_and_move_the_car(tmp_path):
    with open_session(tmp_path) as session:
        session.key_down("w")
        throttles = []
        for _ in range(45):
            session.step()
            throttles.append(session.controls.throttle)
        assert throttles[0] == pytest.approx(2.5 * DT_S)
        assert throttles[-1] == 1.0
        fast = session.observation.speed_mph
        assert fast > 8.0
        session.key_up("w")
        session.key_down("space")
        session.step()
        assert session.controls.brake == 1.0 and session.controls.throttle < 1.0
        session.key_up("space")
        session.key_down("s")  # brakes at speed: negative throttle
        for _ in range(20):
            session.step()
        assert session.controls.throttle == -1.0
        assert session.observation.speed_mph < fast


def test_mouse_steering_follows_the_pointer(tmp_path):
    with open_session(tmp_path) as session:
        session.key_down("m")
        session.key_up("m")
        assert session.steering_source == MOUSE
        session.pointer(0.3)
        assert steer_for(session, 1) == [pytest.approx(0.3)]
        session.pointer(-0.55)
        assert steer_for(session, 1) == [pytest.approx(-0.55)]
        session.pointer(-4.0)  # outside the range: full lock, no more
        assert steer_for(session, 1) == [-1.0]
        session.pointer(0.25)
        session.step()
        session.pointer(None)  # pointer left the window: the wheel stays where it was
        assert steer_for(session, 2) == [pytest.approx(0.25)] * 2
        session.key_down("m")  # back to the keyboard: steering eases back to the centre
        assert session.steering_source == KEYBOARD
        back = steer_for(session, 3)
        assert back[0] == pytest.approx(0.25 - 2.5 * DT_S)
        assert back[-1] == 0.0


def test_a_gamepad_steers_with_its_stick_and_drives_with_its_triggers(tmp_path):
    with open_session(tmp_path) as session:
        session.gamepad_axis("left_x", 0.05)  # inside the dead zone: ignored
        assert session.steering_source == KEYBOARD
        session.gamepad_axis("left_x", 0.54)
        session.gamepad_axis("right_trigger", 1.0)
        assert session.steering_source == GAMEPAD
        for _ in range(15):
            session.step()
        assert session.controls.steering == pytest.approx((0.54 - 0.08) / 0.92)
        assert session.controls.throttle == 1.0
        assert session.observation.speed_mph > 3.0
        session.gamepad_axis("right_trigger", 0.0)
        session.gamepad_axis("left_trigger", 0.5)
        session.step()
        assert session.controls.throttle == pytest.approx(-(0.5 - 0.08) / 0.92)
        session.key_down("arrow_right")  # a steering key takes over from the stick's position
        session.step()
        assert session.steering_source == KEYBOARD
        assert session.controls.steering == pytest.approx((0.54 - 0.08) / 0.92 + 1.2 * DT_S)


def test_the_menu_chooses_track_and_direction_and_escape_goes_back(tmp_path):
    session = DrivingSession(ManualConfig(scenery=False, generated_seed=4), tmp_path / "out",
                             sim_config=STATE_ONLY)
    assert session.step() is None  # nothing to drive in the menu
    lines = session.menu_lines()
    assert "> 1  Lake" in lines and "  3  Generated track (seed 4)" in lines
    session.key_down("arrow_down")
    session.key_up("arrow_down")
    assert session.menu_index == 1
    session.key_down("g")  # another generated track, selected
    session.key_up("g")
    assert session.menu_index == 2 and session.menu_items[2].track == "gen:5"
    session.key_down("arrow_right")  # direction
    session.key_up("arrow_right")
    assert session.reverse and "direction: reverse" in session.menu_lines()
    session.key_down("enter")
    session.key_up("enter")
    obs = session.step()
    assert session.mode == DRIVING and session.track_name == "gen:5"
    assert obs is not None and obs.time_s == 0.0
    assert session.sim.track.name == "gen:5"
    session.key_down("escape")
    session.key_up("escape")
    assert session.mode == MENU and session.sim is None and session.observation is None
    assert not session.quit_requested
    session.key_down("escape")
    assert session.quit_requested


def test_backspace_puts_the_car_back_on_the_centreline(tmp_path):
    with open_session(tmp_path) as session:
        session.key_down("w")
        session.key_down("d")
        for _ in range(40):
            session.step()
        assert abs(session.observation.cte_m) > 1.0
        session.key_up("w")
        session.key_up("d")
        session.key_down("backspace")
        assert session.observation.cte_m == pytest.approx(0.0, abs=1e-6)
        assert session.observation.speed_mph == 0.0


def test_r_records_a_udacity_log_with_every_image(tmp_path):
    with open_session(tmp_path, sim_config=CAMERAS) as session:
        session.key_down("w")
        for _ in range(5):
            session.step()  # driving, not recording yet
        session.key_down("r")
        session.key_up("r")
        assert session.recording
        session.key_down("a")
        labels, speeds = [], []
        for _ in range(12):
            speeds.append(session.observation.speed_mph)
            session.step()
            labels.append(session.controls.steering)
        assert session.rows_recorded == 12
        assert "REC  12 rows" in session.hud().recording
        session.key_down("r")
        session.key_up("r")
        assert not session.recording and session.rows_recorded == 12

        out = tmp_path / "manual"
        log = read_driving_log(out, verify_images="decode")
        assert log.total_rows == 12 and len(log.rows) == 12 and log.skipped == []
        assert not log.has_header
        assert [row.steering for row in log.rows] == pytest.approx(labels, abs=1e-6)
        assert [row.speed_mph for row in log.rows] == pytest.approx(speeds, abs=1e-4)
        assert all(row.throttle == 1.0 and row.brake == 0.0 for row in log.rows)
        times = [image_time(row.center) for row in log.rows]
        gaps = {round((b - a).total_seconds() * 15) for a, b in zip(times, times[1:],
                                                                     strict=False)}
        assert gaps == {1}  # one row per 1/15 s of simulated time
        for row in log.rows:
            assert image_time(row.left) == image_time(row.center) == image_time(row.right)
        config = json.loads((out / "config.json").read_text())
        assert config["style"] == "manual" and config["track"] == "lake"
        assert config["sessions"][-1]["rows"] == 12

        # A second recording appends, its images named after the first one's.
        session.key_down("r")
        for _ in range(4):
            session.step()
        session.key_down("escape")  # leaving the track stops the recording, every row written
        assert session.mode == MENU and not session.recording
        log = read_driving_log(out, verify_images="decode")
        assert len(log.rows) == 16 and log.skipped == []
        assert image_time(log.rows[12].center) > times[-1] + timedelta(milliseconds=60)
        sessions = json.loads((out / "config.json").read_text())["sessions"]
        assert [item["rows"] for item in sessions] == [12, 4]


def test_recording_needs_all_three_cameras(tmp_path):
    with open_session(tmp_path) as session:  # state only: no cameras
        session.key_down("r")
        assert not session.recording
        assert "cannot record" in session.message
        assert not (tmp_path / "manual").exists()


def test_recording_into_a_folder_another_recorder_holds_is_refused(tmp_path):
    from clonedrive.data.recording_lock import RecordingLock

    with RecordingLock(tmp_path / "manual"), open_session(tmp_path, sim_config=CAMERAS) as session:
        session.key_down("r")
        assert not session.recording
        assert "cannot record" in session.message and "another recorder" in session.message
    with open_session(tmp_path, sim_config=CAMERAS) as session:  # free once the other let go
        session.key_down("r")
        session.key_up("r")
        assert session.recording
        session.step()
        session.key_down("r")
        assert not session.recording and session.rows_recorded == 1
    assert not (tmp_path / "manual" / ".clonedrive-recording.lock").exists()


def test_hud_shows_speed_steering_cte_and_recording_state(tmp_path):
    with open_session(tmp_path) as session:
        session.key_down("w")
        session.key_down("d")
        for _ in range(10):
            session.step()
        hud = session.hud()
        obs = session.observation
        assert f"{obs.speed_mph:5.1f} mph" in hud.status
        assert f"steering {session.controls.steering:+.2f}" in hud.status
        assert f"CTE {obs.cte_m:+.2f} m" in hud.status
        assert hud.mode == "MANUAL: keyboard steering"
        assert hud.recording.startswith("not recording")
        assert "R: record" in hud.help and "P: autonomous" in hud.help
        assert len(session.hud_lines()) >= 4


def test_autonomous_mode_without_a_server_says_so(tmp_path, free_port):
    with open_session(tmp_path, sim_config=SimConfig(cameras=("center",), scenery=False),
                      server_port=free_port, connect_timeout_s=0.3) as session:
        session.key_down("p")
        assert session.mode == DRIVING
        assert "cannot connect" in session.message


def test_autonomous_mode_lets_a_drive_server_steer_and_a_key_take_over(tmp_path, tiny_model):
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.udacity.server import DriveServer

    policy = NetworkPolicy(tiny_model, set_speed_mph=9.0)
    with DriveServer(policy, port=0, status_interval_s=0) as server, \
            open_session(tmp_path, sim_config=SimConfig(cameras=("center",), scenery=False),
                         server_port=server.port) as session:
        session.key_down("p")
        session.key_up("p")
        assert session.mode == AUTONOMOUS, session.message
        assert session.hud().mode.startswith("AUTONOMOUS (ws://127.0.0.1:")
        for _ in range(30):
            session.step()
        stats = server.stats()
        assert stats.steer == 30 and stats.bad_total == 0
        assert session.observation.distance_m > 0.5  # the server's PI throttle moved the car
        assert session.controls.throttle == pytest.approx(stats.last_throttle, abs=1e-3)
        assert session.controls.steering == pytest.approx(stats.last_steering, abs=1e-3)

        # Holding a key takes over; the server gets the manual telemetry meanwhile.
        network_steering = session.controls.steering
        session.key_down("a")
        for _ in range(3):
            session.step()
        assert server.stats().manual == 3 and server.stats().steer == 30
        assert session.controls.steering == pytest.approx(network_steering - 3 * 1.2 * DT_S)
        assert "manual override" in session.hud().mode
        session.key_up("a")
        session.step()
        assert server.stats().steer == 31  # released: the server steers again

        session.key_down("p")  # P again: back to manual driving
        assert session.mode == DRIVING
        session.step()
        assert server.stats().steer == 31
