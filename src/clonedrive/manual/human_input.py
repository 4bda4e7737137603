"""A person's hands on the car: keys, the mouse pointer and a gamepad turned into controls.

Steering that gives good labels (UDACITY.md: keyboard steering in the Udacity simulator gives
mostly 0 and then +-1 spikes):

- **keyboard** (arrows or A/D): a held key turns the wheel at ``keyboard_steer_rate_per_s``
  toward full lock; released, the wheel returns to the centre at ``keyboard_return_rate_per_s``.
  One 1/15 s step moves steering by at most ~0.1: ramps, not spikes.
- **mouse** (``M`` toggles): steering follows the pointer's horizontal position, -1 at the
  window's left edge, +1 at its right edge (times ``mouse_gain``, clipped).
- **gamepad**: the left stick's x axis steers, the right trigger drives and the left trigger
  brakes; moving the stick or a trigger beyond ``gamepad_dead_zone`` selects it.

Throttle (W / up arrow) and brake-then-reverse (S / down arrow) ramp at ``throttle_rate_per_s``;
Space brakes fully.

:class:`HumanInput` holds what is pressed, where the pointer is and how far the ramps have
got, and gives one step's controls; it knows nothing of modes, menus or recording, so the
feel of the controls is read and tested on its own.
"""

from __future__ import annotations

import math

from clonedrive.manual.config import ManualConfig
from clonedrive.world.vehicle import Controls

#: Steering sources.
KEYBOARD, MOUSE, GAMEPAD = "keyboard", "mouse", "gamepad"

STEER_LEFT_KEYS = frozenset({"arrow_left", "a"})
STEER_RIGHT_KEYS = frozenset({"arrow_right", "d"})
STEER_KEYS = STEER_LEFT_KEYS | STEER_RIGHT_KEYS
THROTTLE_KEYS = frozenset({"arrow_up", "w"})
REVERSE_KEYS = frozenset({"arrow_down", "s"})
BRAKE_KEYS = frozenset({"space"})
DRIVING_KEYS = STEER_KEYS | THROTTLE_KEYS | REVERSE_KEYS | BRAKE_KEYS
#: Gamepad axes the session reads (Panda3D ``InputDevice.Axis`` names).
GAMEPAD_AXES = ("left_x", "right_trigger", "left_trigger")


def move_toward(value: float, target: float, max_change: float) -> float:
    """``value`` moved toward ``target`` by at most ``max_change`` (>= 0)."""
    if value < target:
        return min(value + max_change, target)
    return max(value - max_change, target)


def dead_zone(value: float, zone: float) -> float:
    """0 inside ``zone``, rescaled so that the output still reaches +-1 outside it."""
    magnitude = abs(value)
    if magnitude <= zone:
        return 0.0
    return math.copysign(min((magnitude - zone) / (1.0 - zone), 1.0), value)


class HumanInput:
    """The input state of one person: keys held (Panda3D button names, lower case), the
    pointer's horizontal position, gamepad axes, the steering source and the keyboard ramps."""

    def __init__(self, config: ManualConfig) -> None:
        self.config = config
        self.source = KEYBOARD  #: the steering source
        self.held: set[str] = set()
        self.key_steering = 0.0  #: where the keyboard's steering ramp is
        self.key_throttle = 0.0  #: where the keys' throttle ramp is
        self.pointer_x: float | None = None
        self.axes = dict.fromkeys(GAMEPAD_AXES, 0.0)

    def press(self, key: str) -> bool:
        """``key`` went down; False when it was held already (auto-repeat)."""
        if key in self.held:
            return False
        self.held.add(key)
        return True

    def release(self, key: str) -> None:
        self.held.discard(key)

    def point(self, x: float | None) -> None:
        """The pointer at ``x`` (clipped to [-1, 1]), or outside the window (None)."""
        self.pointer_x = None if x is None else min(max(float(x), -1.0), 1.0)

    def move_axis(self, axis: str, value: float) -> bool:
        """A gamepad axis moved; True when that made the gamepad the steering source."""
        if axis not in self.axes:
            return False
        self.axes[axis] = float(value)
        if abs(value) > self.config.gamepad_dead_zone and self.source != GAMEPAD:
            self.source = GAMEPAD
            return True
        return False

    def release_all(self) -> None:
        """Every key, the pointer and the gamepad let go."""
        self.held.clear()
        self.pointer_x = None
        self.axes = dict.fromkeys(GAMEPAD_AXES, 0.0)

    def use_keyboard(self, steering: float) -> None:
        """Steer with the keys from here, the ramp starting where the wheel is (``steering``)."""
        self.key_steering = steering
        self.source = KEYBOARD

    def hold(self, steering: float, throttle: float) -> None:
        """Start the keyboard ramps from these values (a reset, or the end of a pilot's turn)."""
        self.key_steering, self.key_throttle = steering, throttle

    def active(self) -> bool:
        """A person is steering or driving now: a driving key held, the pointer steering, or a
        gamepad control beyond the dead zone."""
        zone = self.config.gamepad_dead_zone
        pointing = self.source == MOUSE and self.pointer_x is not None
        return pointing or bool(self.held & DRIVING_KEYS) or any(
            abs(value) > zone for value in self.axes.values())

    def controls(self, dt_s: float, wheel: float) -> Controls:
        """This step's controls after ``dt_s`` [s]; ``wheel``: the steering applied last step
        (kept while the pointer steers from outside the window)."""
        held = self.held
        steering = self._steering(dt_s, wheel)
        key_target = float(bool(held & THROTTLE_KEYS)) - float(bool(held & REVERSE_KEYS))
        self.key_throttle = move_toward(self.key_throttle, key_target,
                                        self.config.throttle_rate_per_s * dt_s)
        throttle = self.key_throttle
        if self.source == GAMEPAD and not held & (THROTTLE_KEYS | REVERSE_KEYS):
            zone = self.config.gamepad_dead_zone  # the triggers set it directly
            throttle = (dead_zone(self.axes["right_trigger"], zone)
                        - dead_zone(self.axes["left_trigger"], zone))
        brake = 1.0 if held & BRAKE_KEYS else 0.0
        return Controls(steering=steering, throttle=throttle, brake=brake).clipped()

    def _steering(self, dt_s: float, wheel: float) -> float:
        """The source's steering; the keyboard ramp moves toward the held side (back to the
        centre when none is held) whichever source steers."""
        config = self.config
        target = (float(bool(self.held & STEER_RIGHT_KEYS))
                  - float(bool(self.held & STEER_LEFT_KEYS))) * config.keyboard_max_steering
        toward_centre = target == 0.0 or target * self.key_steering < 0.0
        rate = config.keyboard_return_rate_per_s if toward_centre else \
            config.keyboard_steer_rate_per_s
        self.key_steering = move_toward(self.key_steering, target, rate * dt_s)
        if self.source == MOUSE:
            if self.pointer_x is None:
                return wheel  # pointer outside the window: hold the wheel
            return min(max(config.mouse_gain * self.pointer_x, -1.0), 1.0)
        if self.source == GAMEPAD:
            return dead_zone(self.axes["left_x"], config.gamepad_dead_zone)
        return self.key_steering
