"""A person's input turned into controls, without a session or a simulator."""

from __future__ import annotations

import pytest

from clonedrive.manual.config import ManualConfig
from clonedrive.manual.human_input import GAMEPAD, KEYBOARD, MOUSE, HumanInput, dead_zone

DT_S = 1.0 / 15.0


def test_a_held_steer_key_ramps_and_a_released_one_returns_to_the_centre() -> None:
    config = ManualConfig()
    hands = HumanInput(config)
    assert hands.press("d") and not hands.press("d")  # the second is auto-repeat
    steps = [hands.controls(DT_S, 0.0).steering for _ in range(3)]
    assert steps == pytest.approx([config.keyboard_steer_rate_per_s * DT_S * n for n in (1, 2, 3)])
    hands.release("d")
    back = hands.controls(DT_S, steps[-1]).steering
    assert back == pytest.approx(max(steps[-1] - config.keyboard_return_rate_per_s * DT_S, 0.0))
    assert hands.active() is False


def test_the_pointer_steers_and_outside_the_window_holds_the_wheel() -> None:
    hands = HumanInput(ManualConfig(mouse_gain=2.0))
    hands.source = MOUSE
    hands.point(0.25)
    assert hands.controls(DT_S, 0.0).steering == pytest.approx(0.5) and hands.active()
    hands.point(None)
    assert hands.controls(DT_S, -0.3).steering == pytest.approx(-0.3) and not hands.active()


def test_a_gamepad_beyond_its_dead_zone_takes_the_wheel_and_its_triggers_drive() -> None:
    hands = HumanInput(ManualConfig(gamepad_dead_zone=0.1))
    assert not hands.move_axis("left_x", 0.05) and hands.source == KEYBOARD
    assert hands.move_axis("right_trigger", 1.0) and hands.source == GAMEPAD
    hands.move_axis("left_x", -1.0)
    controls = hands.controls(DT_S, 0.0)
    assert (controls.steering, controls.throttle) == (-1.0, 1.0)
    hands.release_all()
    assert hands.controls(DT_S, 0.0).throttle == 0.0 and not hands.active()


def test_dead_zone_rescales_so_full_travel_still_reaches_one() -> None:
    assert dead_zone(0.05, 0.1) == 0.0
    assert dead_zone(-1.0, 0.1) == -1.0
    assert dead_zone(0.55, 0.1) == pytest.approx(0.5)
