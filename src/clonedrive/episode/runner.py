"""The episode runner: cars driven in lock-step by a driver, under one set of rules.

Every closed loop in clonedrive goes through this module: recording with the expert
(:mod:`clonedrive.data.recorder`), evaluation (:mod:`clonedrive.evaluate.rollout`), our simulator
as the Udacity client (:mod:`clonedrive.udacity.client`), the manual window
(:mod:`clonedrive.manual.session`) and DAgger. So intervention, lap, time limit and stop reason
mean one thing everywhere (:mod:`clonedrive.episode.rules`).

The pieces:

- :class:`Episode`: one car on an open :class:`~clonedrive.sim.simulator.Simulator` (the caller
  opens and closes it) under :class:`~clonedrive.episode.rules.EpisodeRules`.
  :meth:`Episode.step` applies a :class:`Decision`, intervenes when a tyre leaves the road,
  fills the episode's :class:`~clonedrive.episode.trace.RunTrace` and stops it when a rule says
  so (:attr:`Episode.stopped`).
- a **driver** maps observations to controls. A :class:`Driver` acts for several cars at once
  (one network call for N frames: :class:`~clonedrive.episode.drivers.PolicyDriver`);
  a :class:`CarDriver` drives one car (the expert, a remote drive server, a person) and
  :class:`PerCar` makes a :class:`Driver` of one per car. ``act`` returns :class:`Decision`
  objects (or plain :class:`~clonedrive.world.vehicle.Controls`).
- :class:`Runner`: steps its episodes in lock-step, all active cars per :meth:`Runner.step`,
  until every one has stopped (:meth:`Runner.run`). A second driver, the **labeller**, can be
  asked for its decision on every step, for the same observation the driver saw, without
  steering: its controls are never applied, they are handed back in :attr:`Step.label`.

DAgger, for example: the network drives, the expert labels, every step's frame is written with
the expert's steering::

    episode = Episode(sim, EpisodeRules(laps=1, set_speed_mph=15.0), track="lake")
    runner = Runner([episode], PolicyDriver(policy, [15.0]),
                    labeller=PerCar([ExpertDriver(expert)]))
    for step in runner.steps():            # or runner.run(on_step=...)
        sink.submit(step.seen, step.label.label, step.decision.controls)

The order of one car's step is fixed: the driver (and labeller) decide from the current
observation -> the simulator steps -> the step is traced -> each off-road event is traced and,
under ``off_road="intervene"``, answered by an intervention (the drivers are told, e.g. to reset a
speed controller) -> the stop rules are checked. A runner takes its cars through a step phase
by phase (:meth:`Episode.begin`: every car moves; :meth:`Episode.render`: every car's cameras
draw; :meth:`Episode.finish`: the rest of every car's step), which gives each car the step it
would have alone.

``Runner(..., overlap=True)`` keeps that order for every car but uses a second core: the cars
are split into two fixed halves (even and odd numbers), and while one half's simulators step
and render on the calling thread, a helper thread asks the driver (and labeller) for the other
half's decisions (a network's prediction). Rendering and PyTorch both release Python's lock, so
the two run at once. Each car sees the same observations and decisions as without overlap. A
driver used so must allow ``act`` for some cars while ``reset``/``intervened`` run for others
(``PolicyDriver`` and ``PerCar`` do).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Protocol

from clonedrive.episode.rules import EpisodeRules, Stop
from clonedrive.episode.trace import RunTrace
from clonedrive.sim.laps import OffRoadEvent
from clonedrive.sim.simulator import SimObservation, Simulator
from clonedrive.world.vehicle import Controls

#: Simulated times within this of a limit [s] have reached it (steps are 1/15 s exactly).
TIME_TOLERANCE_S = 1e-9


@dataclass(frozen=True)
class Decision:
    """What a driver decided for one car and one step."""

    controls: Controls  #: what the car applies (for a labeller: what it would apply)
    #: The steering to record as the training label, when it is not the applied steering
    #: (the expert's clean command under steering noise). See :attr:`label`.
    steering_label: float | None = None
    record: bool = True  #: False where the driver does not want the sample recorded
    detail: object = None  #: the driver's own account (the expert's ExpertAction, ...)

    @property
    def label(self) -> float:
        """The steering label: :attr:`steering_label`, else the applied steering."""
        return self.controls.steering if self.steering_label is None else self.steering_label


def as_decision(value: Decision | Controls) -> Decision:
    """A driver's answer as a :class:`Decision` (drivers may answer plain Controls)."""
    if isinstance(value, Decision):
        return value
    if isinstance(value, Controls):
        return Decision(controls=value)
    raise TypeError(f"a driver must answer Decision or Controls, got {type(value).__name__}")


class CarDriver(Protocol):
    """Drives one car."""

    def reset(self) -> None:
        """The car's episode starts: forget filters, integrators, earlier episodes."""

    def act(self, obs: SimObservation) -> Decision | Controls:
        """What to do for the observation ``obs``."""

    def intervened(self, obs: SimObservation) -> None:
        """The car was just put back on the road (an intervention) and now looks like ``obs``."""


class Driver(Protocol):
    """Drives the cars of a :class:`Runner`, numbered ``0..N-1`` in the runner's order, all
    active cars at once."""

    def reset(self, car: int) -> None:
        """Car ``car``'s episode starts."""

    def act(self, cars: Sequence[int], observations: Sequence[SimObservation]
            ) -> Sequence[Decision | Controls]:
        """One decision per car in ``cars``, for the matching observation."""

    def intervened(self, car: int, obs: SimObservation) -> None:
        """Car ``car`` was just put back on the road and now looks like ``obs``."""


class PerCar:
    """A :class:`Driver` made of one :class:`CarDriver` per car (index = car number)."""

    def __init__(self, drivers: Sequence[CarDriver]) -> None:
        self.drivers = list(drivers)

    def reset(self, car: int) -> None:
        self.drivers[car].reset()

    def act(self, cars: Sequence[int], observations: Sequence[SimObservation]
            ) -> list[Decision | Controls]:
        return [self.drivers[car].act(obs) for car, obs in zip(cars, observations, strict=True)]

    def intervened(self, car: int, obs: SimObservation) -> None:
        self.drivers[car].intervened(obs)


@dataclass(frozen=True)
class Step:
    """One car's control step, as the runner hands it to its caller."""

    car: int  #: the car's number in the runner
    seen: SimObservation  #: what the driver (and the labeller) decided from
    decision: Decision  #: the driver's decision; its controls were applied
    label: Decision | None  #: the labeller's decision for ``seen`` (never applied)
    observed: SimObservation  #: right after the step, before any intervention
    events: tuple[OffRoadEvent, ...]  #: tyres that left the road in this step
    lap_completed: bool  #: a clean lap was completed in this step
    intervened: bool  #: the car was put back on the road after this step
    stopped: Stop | None  #: the episode stopped with this step, and why


class Episode:
    """One car's episode on an open simulator (which the caller owns and closes).

    ``track``: the name written into the trace (default: the track's own name); ``seed`` and
    ``options``: passed to :meth:`Simulator.reset`; ``trace``: keep a
    :class:`~clonedrive.episode.trace.RunTrace` of every step (False for open-ended driving).
    """

    def __init__(self, sim: Simulator, rules: EpisodeRules | None = None, *,
                 track: str | None = None, seed: int | None = 0, options: dict | None = None,
                 trace: bool = True) -> None:
        self.sim = sim
        self.rules = rules or EpisodeRules()
        self.track = track if track is not None else sim.track.name
        self.seed = seed
        self.options = dict(options or {})
        self.keep_trace = bool(trace)
        #: Simulated seconds after which the episode stops (None: no limit).
        self.time_limit_s = self.rules.time_limit_s(sim.track.length_m)
        self.trace: RunTrace | None = None
        self.stopped: Stop | None = None
        self.interventions = 0
        self._obs: SimObservation | None = None
        self._begun: tuple[Decision, Decision | None] | None = None  # (decision, label)

    # ------------------------------------------------------------------ state
    @property
    def observation(self) -> SimObservation:
        """The car's current observation (after any intervention)."""
        if self._obs is None:
            raise RuntimeError("the episode has not started: call reset() first")
        return self._obs

    @property
    def done(self) -> bool:
        return self.stopped is not None

    @property
    def laps_started(self) -> int:
        """Laps driven so far, clean or not (the lap being driven is number this + 1)."""
        return self.sim.laps_started

    # ------------------------------------------------------------------ driving
    def reset(self) -> SimObservation:
        """Start (or restart) the episode: place the car, start a new trace."""
        self._obs, _ = self.sim.reset(seed=self.seed, options=self.options)
        self._begun = None
        self.stopped = None
        self.interventions = 0
        self.trace = None
        if self.keep_trace:
            self.trace = RunTrace(track=self.track, speed_mph=self.rules.set_speed_mph,
                                  laps_target=self.rules.laps or 0,
                                  control_hz=self.sim.config.control_hz)
        return self._obs

    def step(self, decision: Decision | Controls, label: Decision | None = None) -> Step:
        """Apply ``decision`` for one control period and apply the rules (see the module).

        The same as :meth:`begin`, :meth:`render` and :meth:`finish` in turn (the runner
        calls those phase by phase for all its cars)."""
        self.begin(decision, label)
        self.render()
        return self.finish()

    def begin(self, decision: Decision | Controls, label: Decision | None = None) -> None:
        """The first part of :meth:`step`: the car moves (:meth:`Simulator.advance`)."""
        if self.stopped is not None:
            raise RuntimeError(f"the episode has stopped ({self.stopped}): reset() it first")
        if self._begun is not None:
            raise RuntimeError("the step has begun already: finish() it first")
        decision = as_decision(decision)
        self.sim.advance(decision.controls)
        self._begun = (decision, label)

    def render(self) -> None:
        """The second part of :meth:`step`: the cameras draw the car's new place."""
        self.sim.render_advanced()

    def finish(self) -> Step:
        """The last part of :meth:`step`: observe, trace, intervene, check the rules."""
        if self._begun is None:
            raise RuntimeError("no step has begun: call begin() first")
        (decision, label), self._begun = self._begun, None
        seen = self.observation
        observed, info = self.sim.finish_step()
        events = tuple(info["events"])
        trace = self.trace
        if trace is not None:
            trace.add_step(observed, decision.controls.steering)
        obs = observed
        intervened = False
        for event in events:
            if trace is not None:
                trace.add_off_road(event)
            if self.rules.off_road == "intervene":
                obs = self.intervene()
                intervened = True
        self._obs = obs
        self.stopped = self._stop_reason(obs)
        if trace is not None:
            trace.laps_completed = obs.laps
            trace.distance_m = obs.distance_m
            self._trace_stop(trace)
        return Step(car=0, seen=seen, decision=decision, label=label, observed=observed,
                    events=events, lap_completed=bool(info["lap_completed"]),
                    intervened=intervened, stopped=self.stopped)

    def intervene(self) -> SimObservation:
        """DESIGN.md's intervention: the car back on the centreline where it is, heading along
        the road, at the set speed. Called by :meth:`step` on an off-road event (and by the
        manual window's Backspace); time, distance and lap progress carry on."""
        self._obs = self.sim.intervene(self.rules.set_speed_mph)
        self.interventions += 1
        return self._obs

    def stop(self, reason: Stop) -> None:
        """Stop the episode from outside (e.g. :attr:`Stop.INTERRUPTED`)."""
        if self.stopped is None:
            self.stopped = Stop(reason)
            if self.trace is not None:
                self._trace_stop(self.trace)

    def _stop_reason(self, obs: SimObservation) -> Stop | None:
        rules = self.rules
        if rules.laps is not None and self.sim.laps_started >= rules.laps:
            return Stop.LAPS
        if (rules.max_off_road_events is not None
                and obs.off_road_events >= rules.max_off_road_events):
            return Stop.OFF_ROAD
        if rules.max_seconds is not None and obs.time_s >= rules.max_seconds - TIME_TOLERANCE_S:
            return Stop.SECONDS
        if self.time_limit_s is not None and obs.time_s >= self.time_limit_s - TIME_TOLERANCE_S:
            return Stop.TIME_LIMIT
        return None

    def _trace_stop(self, trace: RunTrace) -> None:
        trace.stopped = self.stopped
        trace.timed_out = self.stopped in (Stop.SECONDS, Stop.TIME_LIMIT)


class Runner:
    """Steps ``episodes`` in lock-step: per :meth:`step`, one ``driver.act`` call for every
    active car (and one ``labeller.act`` call, if given), then one step of each."""

    def __init__(self, episodes: Sequence[Episode], driver: Driver, *,
                 labeller: Driver | None = None, overlap: bool = False) -> None:
        if not episodes:
            raise ValueError("a runner needs at least one episode")
        self.episodes = list(episodes)
        self.driver = driver
        self.labeller = labeller
        #: Decide for one half of the cars on a helper thread while the other half steps.
        self.overlap = bool(overlap)
        self._started = False
        self._pool: ThreadPoolExecutor | None = None
        #: Decisions being made ahead (overlap): a future of ``{car: (decision, label)}``.
        self._pending: Future | None = None

    @property
    def active(self) -> list[int]:
        """The cars whose episodes have not stopped."""
        return [car for car, episode in enumerate(self.episodes) if not episode.done]

    def reset(self) -> list[SimObservation]:
        """Start every episode, then tell the driver (and labeller) each car starts."""
        self._drop_pending()
        observations = [episode.reset() for episode in self.episodes]
        for car in range(len(self.episodes)):
            self.driver.reset(car)
            if self.labeller is not None:
                self.labeller.reset(car)
        self._started = True
        return observations

    def step(self) -> list[Step]:
        """One control step of every active car (resets first if :meth:`reset` was not
        called). Returns their steps, in car order; [] once every episode has stopped."""
        if not self._started:
            self.reset()
        cars = self.active
        if not cars:
            self._drop_pending()
            return []
        first = [car for car in cars if car % 2 == 0]
        second = [car for car in cars if car % 2 == 1]
        if not (self.overlap and first and second):
            decided = self._take_pending(cars)
            decided.update(self._decide([car for car in cars if car not in decided]))
            return self._step_cars(cars, decided)
        decided = self._take_pending(first)
        decided.update(self._decide([car for car in first if car not in decided]))
        pool = self._pool or ThreadPoolExecutor(1, thread_name_prefix="runner-decide")
        self._pool = pool
        ahead = pool.submit(self._decide, second)
        try:
            steps = self._step_cars(first, decided)
        finally:
            decided = ahead.result()  # never leave the helper deciding unseen
        still = [car for car in first if not self.episodes[car].done]
        if still:  # the first half's next decisions, made while the second half steps
            self._pending = pool.submit(self._decide, still)
        steps += self._step_cars(second, decided)
        return sorted(steps, key=lambda step: step.car)

    def _decide(self, cars: list[int]) -> dict[int, tuple[Decision, Decision | None]]:
        """The driver's (and labeller's) decisions for ``cars``, from their observations."""
        if not cars:
            return {}
        seen = [self.episodes[car].observation for car in cars]
        decisions = _answers(self.driver.act(cars, seen), cars, "driver")
        labels: list[Decision | None] = [None] * len(cars)
        if self.labeller is not None:
            labels = _answers(self.labeller.act(cars, seen), cars, "labeller")
        return {car: (decision, label)
                for car, decision, label in zip(cars, decisions, labels, strict=True)}

    def _step_cars(self, cars: list[int], decided: dict[int, tuple[Decision, Decision | None]]
                   ) -> list[Step]:
        """One step of each of ``cars``, phase by phase: every car moves, then every car's
        cameras draw, then every car's step is finished (each car's step is what it is alone:
        the cars do not meet). The Python of the physics and of the rules then runs together
        instead of between frames, where the renderer has just pushed it out of the CPU's
        caches."""
        for car in cars:
            self.episodes[car].begin(*decided[car])
        for car in cars:
            self.episodes[car].render()
        return [self._finish_car(car) for car in cars]

    def _finish_car(self, car: int) -> Step:
        episode = self.episodes[car]
        step = episode.finish()
        if step.intervened:
            self.driver.intervened(car, episode.observation)
            if self.labeller is not None:
                self.labeller.intervened(car, episode.observation)
        return replace(step, car=car)

    def _take_pending(self, cars: list[int]) -> dict[int, tuple[Decision, Decision | None]]:
        """The decisions made ahead for any of ``cars`` (waiting for them); the others are
        not decided yet. Decisions made ahead for a car that has stopped since are dropped."""
        if self._pending is None:
            return {}
        future, self._pending = self._pending, None
        answers = future.result()
        return {car: answers[car] for car in cars if car in answers}

    def _drop_pending(self) -> None:
        """Wait for any decisions being made ahead, forget them, and stop the helper."""
        if self._pending is not None:
            self._pending.result()
            self._pending = None
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def steps(self) -> Iterator[Step]:
        """Every step of every car until all episodes have stopped."""
        try:
            while True:
                steps = self.step()
                if not steps:
                    return
                yield from steps
        finally:
            self._drop_pending()

    def run(self, on_step: Callable[[Step], None] | None = None) -> list[Episode]:
        """Drive until every episode has stopped; ``on_step`` sees each step as it is taken.
        Returns the episodes (their traces, stop reasons and last observations)."""
        for step in self.steps():
            if on_step is not None:
                on_step(step)
        return self.episodes


def _answers(answers: Sequence[Decision | Controls], cars: Sequence[int], who: str
             ) -> list[Decision]:
    answers = list(answers)
    if len(answers) != len(cars):
        raise ValueError(f"the {who} answered {len(answers)} decisions for {len(cars)} cars")
    return [as_decision(answer) for answer in answers]


def drive(episode: Episode, driver: CarDriver, *, labeller: CarDriver | None = None,
          on_step: Callable[[Step], None] | None = None) -> Episode:
    """Drive one episode with one car driver until it stops (a one-car :class:`Runner`)."""
    runner = Runner([episode], PerCar([driver]),
                    labeller=None if labeller is None else PerCar([labeller]))
    runner.run(on_step)
    return episode
