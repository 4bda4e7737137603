"""What an episode measured, step by step, and its figures (definitions in DESIGN.md).

:class:`RunTrace` is filled by the episode runner (:class:`clonedrive.episode.runner.Episode`)
for every closed loop -- evaluation, the Udacity client, DAgger -- so that each reports the same
figures computed the same way: laps, interventions, autonomy %, mean and max |CTE|, steering
smoothness, mean speed, distance, and why the episode stopped; the first lap's time (when it
was clean) and the smoothness figures of :mod:`clonedrive.episode.smoothness` (steering rate and
jerk, lateral acceleration and jerk), which evaluate and bench divide by the expert's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from clonedrive.episode.smoothness import round_figure, smoothness_figures
from clonedrive.world.vehicle import MPH_TO_MPS

#: NVIDIA (Bojarski et al. 2016): each intervention is charged six seconds.
SECONDS_PER_INTERVENTION = 6.0


def autonomy_pct(interventions: int, elapsed_s: float,
                 penalty_s: float = SECONDS_PER_INTERVENTION) -> float:
    """``(1 - interventions * penalty / elapsed s) * 100``, floored at 0 (penalty: 6 s)."""
    if elapsed_s <= 0:
        return 0.0 if interventions else 100.0
    return max(0.0, (1.0 - interventions * penalty_s / elapsed_s) * 100.0)


def smoothness(steering: np.ndarray, control_hz: float) -> float:
    """Mean |change of steering| per second (steering in [-1, 1]); lower is smoother."""
    steering = np.asarray(steering, dtype=float)
    if len(steering) < 2:
        return 0.0
    return float(np.mean(np.abs(np.diff(steering))) * control_hz)


@dataclass
class OffRoadRecord:
    """Where and when a tyre left the road, and the frame the network saw then."""

    time_s: float
    s_m: float
    x_m: float
    y_m: float
    cte_m: float
    lap: int
    frame_png: str | None = None


@dataclass
class RunTrace:
    """What a closed-loop run measured, one entry per control step."""

    track: str
    speed_mph: float
    laps_target: int
    control_hz: float
    unseen: bool = False
    time_s: list = field(default_factory=list)
    x_m: list = field(default_factory=list)
    y_m: list = field(default_factory=list)
    cte_m: list = field(default_factory=list)
    steering: list = field(default_factory=list)
    speed: list = field(default_factory=list)
    off_road: list[OffRoadRecord] = field(default_factory=list)
    laps_completed: int = 0
    distance_m: float = 0.0
    #: Indices of the steps after which the car was put back on the road (off-road events).
    breaks: list = field(default_factory=list)
    #: Simulated time [s] when the first lap was completed clean (None: not, or not first).
    lap_time_s: float | None = None
    timed_out: bool = False  #: stopped by the time limit or the cap on simulated seconds
    stopped: str | None = None  #: the episode's stop reason (clonedrive.episode.rules.Stop)

    def add_step(self, obs, steering: float) -> None:
        """Record one control step: the observation after it and the steering applied."""
        self.time_s.append(obs.time_s)
        self.x_m.append(obs.x_m)
        self.y_m.append(obs.y_m)
        self.cte_m.append(obs.cte_m)
        self.steering.append(steering)
        self.speed.append(obs.speed_mph)
        if self.lap_time_s is None and obs.laps == 1 and not self.off_road:
            self.lap_time_s = float(obs.time_s)

    def add_off_road(self, event, frame_png: str | None = None) -> None:
        """Record an off-road event (a simulator ``OffRoadEvent``) and the frame seen then."""
        self.off_road.append(OffRoadRecord(
            time_s=event.time_s, s_m=event.s_m, x_m=event.x_m, y_m=event.y_m,
            cte_m=event.cte_m, lap=event.lap, frame_png=frame_png))
        self.breaks.append(len(self.time_s) - 1)

    def summary(self) -> dict:
        """The figures written to eval.json for this run."""
        cte = np.abs(np.asarray(self.cte_m, dtype=float))
        elapsed = float(self.time_s[-1]) if self.time_s else 0.0
        interventions = len(self.off_road)
        return {
            "track": self.track,
            "speed_mph": self.speed_mph,
            "unseen": self.unseen,
            "laps_target": self.laps_target,
            "laps_completed": self.laps_completed,
            "interventions": interventions,
            "autonomy_pct": round(autonomy_pct(interventions, elapsed), 2),
            "mean_abs_cte_m": round(float(cte.mean()) if len(cte) else 0.0, 3),
            "max_abs_cte_m": round(float(cte.max()) if len(cte) else 0.0, 3),
            "smoothness": round_figure(smoothness(self.steering, self.control_hz)),
            "mean_speed_mph": round(float(np.mean(self.speed)) if self.speed else 0.0, 2),
            "distance_m": round(self.distance_m, 1),
            "elapsed_s": round(elapsed, 2),
            "lap_time_s": None if self.lap_time_s is None else round(self.lap_time_s, 3),
            **smoothness_figures(self.steering, self.x_m, self.y_m,
                                 np.asarray(self.speed, dtype=float) * MPH_TO_MPS,
                                 self.control_hz, self.breaks),
            "timed_out": self.timed_out,
            "stopped": None if self.stopped is None else str(self.stopped),
            "off_road_events": [
                {"time_s": round(e.time_s, 2), "s_m": round(e.s_m, 1), "x_m": round(e.x_m, 1),
                 "y_m": round(e.y_m, 1), "cte_m": round(e.cte_m, 2), "lap": e.lap,
                 "frame_png": e.frame_png}
                for e in self.off_road
            ],
        }
