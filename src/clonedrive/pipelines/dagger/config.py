"""What ``clonedrive dagger`` runs: :class:`DaggerConfig`, and the names of its files."""

from __future__ import annotations

import math
from dataclasses import dataclass

from clonedrive.bench import DEFAULT_SUITE
from clonedrive.model.train_config import MAX_LEARNING_RATE
from clonedrive.sim.engine import DEFAULT_RENDERER
from clonedrive.world.vehicle import TOP_SPEED_MPH, check_set_speed

DAGGER_JSON = "dagger.json"
DAGGER_PNG = "dagger.png"
#: Settings a rerun into a DAgger folder may change: more iterations extend it (iteration k
#: does not depend on how many follow), workers only share the work, and the plain-cloning
#: folders check their own recording (noise, label count) before they are reused.
RERUN_MAY_CHANGE = ("iterations", "workers", "plain", "plain_each", "plain_noise")
#: Start of the image names of DAgger recordings (reproducible names, like the demo's).
START_TIME = "2026-01-01T12:00:00"


@dataclass(frozen=True)
class DaggerConfig:
    """What ``clonedrive dagger`` runs (see the module doc)."""

    iterations: int = 5
    beta: float = 0.5  #: share of steps the expert drives in iteration 1
    beta_decay: float = 0.5  #: beta_k = beta * beta_decay ** (k - 1)
    tracks: tuple[str, ...] = ("mountain", "lake")  #: where labels are collected
    laps: int = 1  #: laps per track and iteration
    speed_mph: float = TOP_SPEED_MPH  #: set speed (a cap) while collecting and evaluating
    epochs: int = 2  #: training epochs per iteration, from the previous weights
    learning_rate: float = 5e-4
    eval_tracks: tuple[str, ...] = ("mountain", "lake")
    eval_laps: int = 1
    eval_unseen: int = 3  #: generated tracks evaluate never records on (split ``unseen``)
    bench_suite: str = DEFAULT_SUITE  #: the benchmark suite evaluating each iteration ...
    bench_splits: tuple[str, ...] = ()  #: ... on these splits (none: evaluate's tracks)
    workers: int | None = 1  #: bench worker processes
    takeover_margin_m: float = 0.3  #: the expert takes over this near an edge [m]
    takeover_preview_s: float = 1.0  #: ... judged now and this far ahead on the heading [s]
    takeover_release_cte_m: float = 0.5  #: the network gets the car back within this of centre
    takeover_min_s: float = 1.0  #: a takeover lasts at least this long [s]
    plain: bool = True  #: also train plain cloning with as many extra expert labels
    #: ... and at every earlier iteration's label count too (the comparison as a curve)
    plain_each: bool = False
    plain_noise: float = 0.15  #: the expert's steering noise recording those labels
    seed: int = 0
    max_seconds: float | None = None  #: cap per episode (quick runs)
    scenery: bool = True
    #: recordings of a person's takeovers (``clonedrive web``), aggregated from iteration 1
    human: tuple[str, ...] = ()
    renderer: str = DEFAULT_RENDERER  #: who draws frames (sim/engine.py), collecting and after
    #: evaluate on whole frames, not only the rows the network's crop keeps (collection always
    #: renders whole frames: they are recorded)
    full_frame: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "human", tuple(str(folder) for folder in self.human))
        if self.iterations < 1:
            raise ValueError(f"iterations must be at least 1, got {self.iterations}")
        for name in ("beta", "beta_decay"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {value}")
        if not self.tracks:
            raise ValueError("give at least one track to collect on")
        if not self.eval_tracks and not self.eval_unseen:
            raise ValueError("give at least one evaluation track (or eval_unseen)")
        check_set_speed(self.speed_mph)
        for name in ("laps", "epochs", "eval_laps"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.eval_unseen < 0:
            raise ValueError(f"eval_unseen must be >= 0, got {self.eval_unseen}")
        if not 0 < self.learning_rate <= MAX_LEARNING_RATE:  # also NaN and infinity
            raise ValueError(f"learning_rate must be in (0, {MAX_LEARNING_RATE:g}], got "
                             f"{self.learning_rate}")
        for name in ("takeover_margin_m", "takeover_preview_s", "takeover_release_cte_m",
                     "takeover_min_s"):
            if not (getattr(self, name) >= 0 and math.isfinite(getattr(self, name))):
                raise ValueError(f"{name} must be a finite number >= 0")
        if not 0.0 <= self.plain_noise <= 1.0:
            raise ValueError(f"plain_noise must be in [0, 1], got {self.plain_noise}")
        if self.max_seconds is not None and not (math.isfinite(self.max_seconds)
                                                 and self.max_seconds > 0):
            raise ValueError(f"max_seconds must be a positive number of seconds, got "
                             f"{self.max_seconds}")

    def beta_at(self, iteration: int) -> float:
        """The expert's share of the steps in iteration ``iteration`` (1-based)."""
        return self.beta * self.beta_decay ** (iteration - 1)
