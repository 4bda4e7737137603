"""Laps and off-road events: what the simulator counts as the car goes round (DESIGN.md).

- **off-road event**: the moment any tyre's contact point leaves the road surface, checked every
  control step (one event per departure: a car that stays off the road is one event).
- **lap completed**: the car crosses the start line again having covered the whole track in the
  driving direction with no off-road event. A lap driven with an event is *started* and
  finished (it counts in :attr:`LapCounter.lap_index`) but not *completed*.

:class:`LapCounter` holds that state for one episode and knows nothing else: the simulator feeds
it the car's arc length and whether it is on the road after every step.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class OffRoadEvent:
    """A tyre left the road."""

    time_s: float
    s_m: float  #: arc length in the driving direction
    x_m: float
    y_m: float
    cte_m: float
    lap: int  #: index of the lap being driven (0 = first)


@dataclass(frozen=True)
class LapUpdate:
    """What one step changed."""

    event: OffRoadEvent | None  #: the car left the road in this step
    lap_completed: bool  #: a clean lap was completed in this step


class LapCounter:
    """Progress, laps and off-road events of one episode on a track of ``length_m``."""

    def __init__(self, length_m: float) -> None:
        if not length_m > 0:
            raise ValueError(f"track length must be positive, got {length_m}")
        self.length_m = float(length_m)
        self.restart(0.0, off_road=False)

    def restart(self, s_m: float, *, off_road: bool) -> None:
        """A new episode starting at arc length ``s_m`` (in the driving direction)."""
        self.laps = 0  #: clean laps completed
        self.lap_index = 0  #: index of the lap being driven = laps started and finished
        self.events: list[OffRoadEvent] = []
        self._s_m = float(s_m)
        self._progress_m = 0.0  # signed distance covered along the driving direction
        self._lap_clean = True
        self._off_road = bool(off_road)

    def placed(self, s_m: float, *, off_road: bool) -> None:
        """The car was put somewhere on the track (an intervention) without driving there:
        progress and laps carry on, and a car put down off the road is no new event."""
        self._s_m = float(s_m)
        self._off_road = bool(off_road)

    def update(self, *, s_m: float, off_road: bool, time_s: float, x_m: float, y_m: float,
               cte_m: float) -> LapUpdate:
        """The car is at ``s_m`` after a step, on the road or not."""
        length = self.length_m
        self._progress_m += (s_m - self._s_m + 0.5 * length) % length - 0.5 * length
        self._s_m = s_m
        event = None
        if off_road and not self._off_road:
            event = OffRoadEvent(time_s=time_s, s_m=s_m, x_m=x_m, y_m=y_m, cte_m=cte_m,
                                 lap=self.lap_index)
            self.events.append(event)
            self._lap_clean = False
        self._off_road = off_road
        lap_completed = False
        if self._progress_m >= (self.lap_index + 1) * length:
            if self._lap_clean:
                self.laps += 1
                lap_completed = True
            self.lap_index += 1
            self._lap_clean = not off_road
        return LapUpdate(event=event, lap_completed=lap_completed)

    @property
    def lap_progress(self) -> float:
        """Fraction of the current lap covered, 0..1."""
        progress = self._progress_m / self.length_m - self.lap_index
        return float(min(max(progress, 0), 1))
