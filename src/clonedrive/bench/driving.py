"""What a bench worker does: drive one batch of a suite's episodes in lock-step.

:func:`drive_batch` runs in a worker process of :mod:`clonedrive.base.workers`. A **model batch**
loads the model once and drives its episodes through the episode runner
(:mod:`clonedrive.episode`) in lock-step, their frames batched through the network; each car
has its episode's conditions (sim/conditions.py), its own PI speed controller and, under a
latency condition, a queue that holds its decisions back that many control steps. An **expert
batch** drives the reference laps: the expert (state only, no cameras) once per (track, speed
cap, direction, start). Both return plain dicts (what bench.json keeps per run), in the
batch's order.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

from clonedrive.bench.suite import EpisodeSpec
from clonedrive.episode.rules import EpisodeRules
from clonedrive.episode.runner import Decision, Episode, PerCar, Runner, Step
from clonedrive.sim.camera_pool import CameraPool
from clonedrive.sim.engine import DEFAULT_RENDERER
from clonedrive.sim.simulator import Controls, SimConfig, SimObservation, Simulator


@dataclass(frozen=True)
class BatchTask:
    """One batch for a worker: a model's episodes, or the expert's reference laps."""

    kind: str  #: "model" or "expert"
    episodes: tuple[EpisodeSpec, ...]
    max_seconds: float | None = None  #: cap per episode (quick runs)
    scenery: bool = True
    renderer: str = DEFAULT_RENDERER
    full_frame: bool = False  #: render whole frames, not only the model's crop
    latency: bool = False  #: expert: obey as late as each episode's conditions say
    model: str = ""  #: model: the file
    label: str = ""  #: model: its method's name
    entry: str = ""  #: model: as given on the command line (LABEL=PATH or PATH)
    policy_options: dict = field(default_factory=dict)  #: NetworkPolicy's options
    trust_model: bool = False
    runtime: str = "auto"
    portable: object = None  #: the model's checked traces (NetworkPolicy.portable), or None


#: What a delayed car applies before its first decision arrives: coast straight.
_NEUTRAL = Decision(controls=Controls(steering=0.0, throttle=0.0))


class DelayedDriver:
    """Wraps a runner :class:`~clonedrive.episode.runner.Driver`: car ``i``'s decisions are
    applied ``latency_steps[i]`` control steps after they are made (actuation latency). The
    wrapped driver still decides from the current observation every step."""

    def __init__(self, driver, latency_steps: Sequence[int]) -> None:
        self.driver = driver
        self.latency_steps = [int(k) for k in latency_steps]
        self._queues = [deque([_NEUTRAL] * k) for k in self.latency_steps]

    def reset(self, car: int) -> None:
        self.driver.reset(car)
        self._queues[car] = deque([_NEUTRAL] * self.latency_steps[car])

    def act(self, cars: Sequence[int], observations: Sequence[SimObservation]) -> list:
        decided = self.driver.act(cars, observations)
        out = []
        for car, decision in zip(cars, decided, strict=True):
            queue = self._queues[car]
            queue.append(decision)
            out.append(queue.popleft())
        return out

    def intervened(self, car: int, obs: SimObservation) -> None:
        self.driver.intervened(car, obs)  # decisions already in flight still arrive


def _result(spec: EpisodeSpec, episode: Episode, lap_time_s: float | None) -> dict:
    summary = episode.trace.summary()
    for key in ("unseen", "off_road_events"):
        summary.pop(key, None)
    summary.update({
        "key": spec.key, "split": spec.split, "index": spec.index, "family": spec.family,
        "conditions_seed": spec.seed, "conditions": spec.conditions.to_dict(),
        "lap_time_s": None if lap_time_s is None else round(lap_time_s, 3),
        "clean": bool(summary["laps_completed"] >= spec.laps),
        "route_m": round(float(episode.sim.track.length_m) * spec.laps, 1),
        "reverse": spec.reverse, "start_fraction": spec.start_fraction,
    })
    return summary


def _drive(episodes: list[Episode], driver, specs: Sequence[EpisodeSpec]) -> list[dict]:
    lap_times: dict[int, float] = {}

    def on_step(step: Step) -> None:
        if step.lap_completed and step.car not in lap_times:
            lap_times[step.car] = step.observed.time_s

    Runner(episodes, driver).run(on_step)
    return [_result(spec, episode, lap_times.get(car))
            for car, (spec, episode) in enumerate(zip(specs, episodes, strict=True))]


def drive_batch(task: BatchTask) -> list[dict]:
    """Drive one batch (a model's episodes, or the expert's laps: with ``latency`` as late as
    the episodes say, the references are driven without). Returns one result dict per
    episode, in order."""
    specs = list(task.episodes)
    rules = {"max_seconds": task.max_seconds}
    if task.kind == "expert":
        return _drive_expert(specs, rules, latency=task.latency)
    return _drive_model(task.model, specs, rules, policy_options=dict(task.policy_options),
                        trust=task.trust_model, runtime=task.runtime, scenery=task.scenery,
                        portable=task.portable, renderer=task.renderer,
                        full_frame=task.full_frame)


def _episodes(sims: list[Simulator], specs: list[EpisodeSpec], rules: dict) -> list[Episode]:
    return [Episode(sim, EpisodeRules(laps=spec.laps, set_speed_mph=spec.speed_mph, **rules),
                    track=spec.track, seed=0, options=spec.reset_options(sim.track.length_m))
            for sim, spec in zip(sims, specs, strict=True)]


def _drive_model(model_path: str, specs: list[EpisodeSpec], rules: dict, *,
                 policy_options: dict, scenery: bool, trust: bool = False,
                 runtime: str = "auto", portable=None, renderer: str = DEFAULT_RENDERER,
                 full_frame: bool = False) -> list[dict]:
    """``portable``: the model's checked traces (NetworkPolicy.portable), run by PyTorch alone
    instead of loading the model file with Keras; the same steering to the last bit. Frames
    are drawn by ``renderer``; only the rows the model's crop keeps unless ``full_frame``."""
    from clonedrive.base.keras_backend import compute_threads
    from clonedrive.drivers.policy import load_policy
    from clonedrive.episode.drivers import PolicyDriver

    policy = load_policy(model_path, trust=trust, runtime=runtime, portable=portable,
                         **policy_options)
    rows = None if full_frame else policy.visible_rows
    sims = []
    pool = CameraPool()  # the runs on one track in one look share a scene
    try:
        for spec in specs:
            config = SimConfig(cameras=("center",), scenery=scenery, conditions=spec.conditions,
                               renderer=renderer, render_rows=rows)
            sims.append(Simulator(spec.track, config, pool=pool))
        episodes = _episodes(sims, specs, rules)
        driver = PolicyDriver(policy, [spec.speed_mph for spec in specs])
        latency = [spec.conditions.latency_steps for spec in specs]
        if any(latency):
            driver = DelayedDriver(driver, latency)
        # One compute thread: results must not depend on how many workers share the cores. Set
        # for the drive only, so that a caller's own process keeps its setting.
        with compute_threads(1):
            return _drive(episodes, driver, specs)
    finally:
        for sim in sims:
            sim.close()
        pool.close()


def _drive_expert(specs: list[EpisodeSpec], rules: dict, *, latency: bool = False
                  ) -> list[dict]:
    """The expert's laps of ``specs`` (state only). With ``latency`` each car obeys as late as
    its episode's conditions say, as a network's would: whether the expert can drive an
    episode clean at all (a suite's episodes must stay within physics)."""
    from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy
    from clonedrive.episode.drivers import ExpertDriver

    sims = [Simulator(spec.track, SimConfig(cameras=())) for spec in specs]
    try:
        episodes = _episodes(sims, specs, rules)
        cars = [ExpertDriver(ExpertPolicy(sim.track, ExpertConfig(speed_mph=spec.speed_mph,
                                                               reverse=spec.reverse)))
                for sim, spec in zip(sims, specs, strict=True)]
        driver = PerCar(cars)
        delays = [spec.conditions.latency_steps for spec in specs]
        if latency and any(delays):
            driver = DelayedDriver(driver, delays)
        return _drive(episodes, driver, specs)
    finally:
        for sim in sims:
            sim.close()
