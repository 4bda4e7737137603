"""What ``clonedrive evaluate`` runs: :class:`EvalConfig` (frozen, validated; the command's
option defaults come from it) and the runs it stands for (:func:`run_specs`).

Kept apart from the rollout so that reading the defaults loads neither the simulator nor Keras.
"""

from __future__ import annotations

from dataclasses import dataclass

from clonedrive.episode.rules import TIME_LIMIT_FACTOR, EpisodeRules
from clonedrive.sim.engine import DEFAULT_RENDERER, check_renderer
from clonedrive.world.vehicle import TOP_SPEED_MPH, check_set_speed

#: Generated tracks used as unseen tracks start at this seed; recordings never use them.
UNSEEN_SEED_BASE = 1000
#: The car's top speed [mph]: set speeds above it cannot be held.
MAX_SET_SPEED_MPH = TOP_SPEED_MPH
#: The largest count each option takes: a list of runs is built before anything drives, so
#: ``--unseen 1000000000`` would fill the memory instead of starting.
MAX_COUNTS = {"laps": 1000, "unseen": 10_000, "unseen_laps": 1000, "batch": 1024,
              "workers": 1024}


def _check_speed(name: str, value: float) -> None:
    check_set_speed(value, name)


@dataclass(frozen=True)
class EvalConfig:
    """What ``clonedrive evaluate`` runs."""

    tracks: tuple[str, ...] = ("lake",)
    speeds_mph: tuple[float, ...] = (15.0,)
    laps: int = 2
    unseen: int = 0  #: also drive this many generated tracks never used in recording
    unseen_speed_mph: float | None = None  #: speed on unseen tracks (default: the first speed)
    unseen_laps: int | None = None  #: laps on unseen tracks (default: laps)
    video: bool = False
    #: the hand-made curve rule (target speed falls as the predicted steering grows); None:
    #: as the policy drives (the model file's own setting)
    slow_in_curves: bool | None = None
    scenery: bool = True
    batch: int = 8  #: runs driven in lock-step (by one process, rendering beside the network)
    #: worker processes the runs are spread over (None: one per CPU core); each drives its
    #: share of the runs in lock-step. Needs the model's file; 1 drives in this process.
    workers: int | None = None
    time_limit_factor: float = TIME_LIMIT_FACTOR  #: stop after this x the laps' time at set speed
    max_seconds: float | None = None  #: cap on simulated time per run (quick checks)
    #: Each run also gets the expert's figures on the same track and cap, and the ratios
    #: (lap time, smoothness) to them (evaluate.reference).
    expert_reference: bool = True
    video_saliency: bool = False  #: paint the VisualBackProp mask onto the video frames
    renderer: str = DEFAULT_RENDERER  #: "auto", "software" or "egl" (sim/engine.py)
    #: render whole frames even where the network looks at fewer rows (runs with video always
    #: get whole frames; the others only the rows the model's crop keeps)
    full_frame: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.tracks, str) or not all(isinstance(t, str) and t for t in self.tracks):
            raise ValueError(f"tracks must be a tuple of track names, got {self.tracks!r}")
        if not self.speeds_mph:
            raise ValueError("give at least one set speed")
        check_renderer(self.renderer)
        for speed in self.speeds_mph:
            _check_speed("each set speed", speed)
        if self.unseen_speed_mph is not None:
            _check_speed("unseen_speed_mph", self.unseen_speed_mph)
        if self.workers is not None and self.workers < 1:
            raise ValueError(f"workers must be at least 1, got {self.workers}")
        for name in ("laps", "batch"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.unseen < 0:
            raise ValueError(f"unseen must be >= 0, got {self.unseen}")
        if self.unseen_laps is not None and self.unseen_laps < 1:
            raise ValueError(f"unseen_laps must be at least 1, got {self.unseen_laps}")
        for name, most in MAX_COUNTS.items():
            value = getattr(self, name)
            if value is not None and value > most:
                raise ValueError(f"{name} must be at most {most}, got {value}")
        if not self.tracks and not self.unseen:
            raise ValueError("nothing to evaluate: give at least one track (or --unseen N)")
        # The episode rules check the time limit and the cap on seconds.
        EpisodeRules(laps=self.laps, set_speed_mph=self.speeds_mph[0],
                     max_seconds=self.max_seconds, time_limit_factor=self.time_limit_factor)


@dataclass(frozen=True)
class RunSpec:
    track: str
    speed_mph: float
    laps: int
    unseen: bool = False


def run_specs(config: EvalConfig) -> list[RunSpec]:
    specs = [RunSpec(t, float(v), config.laps) for t in config.tracks for v in config.speeds_mph]
    unseen_speed = config.unseen_speed_mph or config.speeds_mph[0]
    unseen_laps = config.unseen_laps or config.laps
    specs += [RunSpec(f"gen:{UNSEEN_SEED_BASE + i}", float(unseen_speed), unseen_laps, True)
              for i in range(config.unseen)]
    return specs
