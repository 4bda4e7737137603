"""The rules of an episode: when the car is put back on the road, and when an episode stops.

One definition each, used by every closed loop (record, evaluate, autonomous, the manual window,
DAgger):

- **intervention** (DESIGN.md, after NVIDIA's Bojarski et al. 2016): when a tyre leaves the road
  the car is put back on the centreline at that point, heading along the road, at the episode's
  **set speed** (:attr:`EpisodeRules.set_speed_mph`), and driving goes on. With
  ``off_road="continue"`` the event is counted and the car drives on from where it is (the
  expert recovers by itself while recording; a person drives where they like).
- **lap completed**: the simulator's :class:`~clonedrive.sim.laps.LapCounter`.
- **time limit**: :func:`time_limit_s`, ``2.5 x`` the time the target laps take at the set speed
  plus 30 s, so that a stalled or circling car stops.
- **stop reasons**: :class:`Stop`, checked after every step in this order: the target laps were
  driven, too many off-road events, the cap on simulated seconds, the time limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from clonedrive.world.vehicle import MPH_TO_MPS

#: The time limit allows this many times the time the laps take at the set speed...
TIME_LIMIT_FACTOR = 2.5
#: ... plus this much [s] (starting from rest, slowing for curves).
TIME_LIMIT_MARGIN_S = 30.0
#: What happens when a tyre leaves the road.
OFF_ROAD_POLICIES = ("intervene", "continue")


class Stop(StrEnum):
    """Why an episode stopped (written as the plain string into summaries and eval.json)."""

    LAPS = "laps"  #: the target number of laps was driven (clean or not)
    OFF_ROAD = "off_road"  #: ``max_off_road_events`` off-road events
    SECONDS = "seconds"  #: ``max_seconds`` of simulated time (a cap the user asked for)
    TIME_LIMIT = "time_limit"  #: :func:`time_limit_s` passed before the laps were driven
    INTERRUPTED = "interrupted"  #: stopped from outside (Ctrl-C, a window closed)


def time_limit_s(track_length_m: float, laps: int, set_speed_mph: float,
                 factor: float = TIME_LIMIT_FACTOR) -> float:
    """Simulated seconds an episode of ``laps`` laps at ``set_speed_mph`` may take:
    ``factor x laps x length / set speed + 30 s``."""
    return factor * laps * track_length_m / (set_speed_mph * MPH_TO_MPS) + TIME_LIMIT_MARGIN_S


@dataclass(frozen=True)
class EpisodeRules:
    """The rules one episode is driven by."""

    #: Laps to drive; the episode stops once that many have been driven (clean or not).
    #: None: no lap target and no time limit (a person driving until they stop).
    laps: int | None = 1
    #: Interventions put the car back at this speed [mph]; the time limit is computed from it.
    #: 0 (a person, who holds no set speed): the car is put back at rest, no time limit.
    set_speed_mph: float = 15.0
    off_road: str = "intervene"  #: one of :data:`OFF_ROAD_POLICIES`
    max_off_road_events: int | None = None  #: stop after this many off-road events
    max_seconds: float | None = None  #: stop after this much simulated time [s]
    time_limit_factor: float = TIME_LIMIT_FACTOR  #: see :func:`time_limit_s`

    def __post_init__(self) -> None:
        if self.laps is not None and (isinstance(self.laps, bool) or self.laps < 1):
            raise ValueError(f"laps must be at least 1 (or None), got {self.laps}")
        if not (math.isfinite(self.set_speed_mph) and self.set_speed_mph >= 0):
            raise ValueError(f"set_speed_mph must be a finite speed >= 0, got "
                             f"{self.set_speed_mph}")
        if self.off_road not in OFF_ROAD_POLICIES:
            raise ValueError(f"off_road must be one of {', '.join(OFF_ROAD_POLICIES)}, got "
                             f"{self.off_road!r}")
        if self.max_off_road_events is not None and self.max_off_road_events < 1:
            raise ValueError(f"max_off_road_events must be at least 1 (or None), got "
                             f"{self.max_off_road_events}")
        if self.max_seconds is not None and not (math.isfinite(self.max_seconds)
                                                 and self.max_seconds > 0):
            raise ValueError(f"max_seconds must be a positive number of seconds (or None), got "
                             f"{self.max_seconds}")
        if not (math.isfinite(self.time_limit_factor) and self.time_limit_factor > 0):
            raise ValueError(f"time_limit_factor must be positive, got {self.time_limit_factor}")

    def time_limit_s(self, track_length_m: float) -> float | None:
        """This episode's time limit on a track of ``track_length_m`` (None: none)."""
        if self.laps is None or self.set_speed_mph <= 0:
            return None
        return time_limit_s(track_length_m, self.laps, self.set_speed_mph,
                            self.time_limit_factor)
