"""What ``clonedrive sim`` and ``clonedrive web`` take: :class:`ManualConfig` (frozen, validated;
the commands' option defaults come from it) and where ``R`` records unless told otherwise.

Kept apart from the session so that reading the defaults loads neither the simulator nor the
recorder, and so that how manual driving feels (the ramps, the dead zone) is read in one place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from clonedrive.base.udacity_spec import JPEG_QUALITY, PORT

#: Where ``R`` records unless told otherwise.
DEFAULT_OUT_DIR = "data/manual"


@dataclass(frozen=True)
class ManualConfig:
    """How manual driving feels and where autonomous mode connects."""

    keyboard_steer_rate_per_s: float = 1.2  #: steering change per s while a steer key is held
    keyboard_return_rate_per_s: float = 2.5  #: ... back toward 0 when released or reversing
    keyboard_max_steering: float = 1.0  #: the most a held key steers (|steering|)
    throttle_rate_per_s: float = 2.5  #: throttle change per s toward the key's target
    mouse_gain: float = 1.0  #: steering = gain x pointer x (pointer x in [-1, 1])
    gamepad_dead_zone: float = 0.08  #: stick/trigger values below this count as 0
    scenery: bool = True  #: trees, rocks... (off: road and terrain only, quicker to load)
    seed: int = 0  #: the scene's seed
    generated_seed: int = 1  #: the menu's generated track is gen:<this>, G picks the next
    header: bool = False  #: recording: write the header line (the simulator writes none)
    relative_paths: bool = False  #: recording: IMG/<name> instead of absolute paths
    jpeg_quality: int = JPEG_QUALITY  #: recording: JPEG quality 1-100
    server_host: str = "127.0.0.1"  #: autonomous mode: the drive server
    server_port: int = PORT
    connect_timeout_s: float = 2.0  #: give up connecting after this long (the window waits)
    reply_timeout_s: float = 10.0  #: a drive server silent this long ends autonomous mode

    def __post_init__(self) -> None:
        for name in ("keyboard_steer_rate_per_s", "keyboard_return_rate_per_s",
                     "throttle_rate_per_s", "mouse_gain", "connect_timeout_s",
                     "reply_timeout_s"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {getattr(self, name)}")
        if not 0 < self.keyboard_max_steering <= 1:
            raise ValueError(
                f"keyboard_max_steering must be in (0, 1], got {self.keyboard_max_steering}")
        if not 0 <= self.gamepad_dead_zone < 1:
            raise ValueError(f"gamepad_dead_zone must be in [0, 1), got {self.gamepad_dead_zone}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in [1, 100], got {self.jpeg_quality}")
        if not 0 <= self.server_port <= 65535:
            raise ValueError(f"server_port must be in 0..65535, got {self.server_port}")
