"""The replayed car's motion relative to the recorded one (replay.motion), for both vehicle
models."""

from __future__ import annotations

import pytest

from clonedrive.replay.motion import VEHICLE_MODELS, RelativeMotion

FRAME_S = 1.0 / 15.0


def drive(model: str, steering: float, recorded: float, speed_mph: float,
          frames: int) -> RelativeMotion:
    motion = RelativeMotion(model)
    for _ in range(frames):
        motion.advance(steering, recorded, speed_mph, FRAME_S)
    return motion


@pytest.mark.parametrize("model", VEHICLE_MODELS)
def test_the_same_steering_keeps_the_car_on_the_recorded_path(model: str) -> None:
    motion = drive(model, 0.3, 0.3, 30.0, 45)  # 3 s in a tight curve at 30 mph
    assert abs(motion.offset_m) < 1e-9 and abs(motion.heading_rad) < 1e-9


@pytest.mark.parametrize("model", VEHICLE_MODELS)
def test_steering_further_right_moves_the_car_right_and_back(model: str) -> None:
    right = drive(model, 0.05, 0.0, 30.0, 15)
    left = drive(model, -0.05, 0.0, 30.0, 15)
    assert right.offset_m > 0.1 and right.heading_rad > 0.0
    assert left.offset_m == pytest.approx(-right.offset_m, rel=1e-6)
    right.put_back()
    assert (right.offset_m, right.heading_rad) == (0.0, 0.0)
    right.advance(0.0, 0.0, 30.0, FRAME_S)  # put back moving as the recorded car
    assert abs(right.offset_m) < 1e-9


def test_at_speed_the_dynamic_car_turns_later_than_the_kinematic_one() -> None:
    # Yaw inertia and tyre slip: a step of steering turns the dynamic car more slowly at first
    # (and, understeering, less in the end) than the kinematic bicycle.
    for frames in (3, 30):
        dynamic = drive("dynamic", 0.05, 0.0, 30.0, frames)
        kinematic = drive("kinematic", 0.05, 0.0, 30.0, frames)
        assert 0.0 < dynamic.heading_rad < kinematic.heading_rad
        assert 0.0 < dynamic.offset_m < kinematic.offset_m


def test_at_walking_pace_both_models_turn_alike() -> None:
    # Below 2 m/s the simulator's model is the kinematic one; only the reference point (the
    # centre of gravity, not the rear axle) differs.
    dynamic = drive("dynamic", 0.2, 0.0, 3.0, 30)
    kinematic = drive("kinematic", 0.2, 0.0, 3.0, 30)
    assert dynamic.heading_rad == pytest.approx(kinematic.heading_rad, rel=0.02)


def test_a_stopped_car_does_not_move_and_a_bad_model_is_refused() -> None:
    motion = RelativeMotion("dynamic")
    assert motion.advance(1.0, 0.0, 0.0, FRAME_S) == 0.0
    assert (motion.offset_m, motion.heading_rad) == (0.0, 0.0)
    with pytest.raises(ValueError, match="vehicle model must be one of kinematic, dynamic"):
        RelativeMotion("bicycle")
