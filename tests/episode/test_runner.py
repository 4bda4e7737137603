"""The episode runner: interventions, time limit, laps, stop reasons, lock-step and labeller.

State-only simulators (no cameras), so these run in a few seconds; the drivers are plain
feedback laws written here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from clonedrive.episode.rules import EpisodeRules, Stop, time_limit_s
from clonedrive.episode.runner import Decision, Episode, PerCar, Runner, drive
from clonedrive.sim.simulator import Controls, SimConfig, Simulator
from clonedrive.world.vehicle import MPH_TO_MPS

STATE_ONLY = SimConfig(cameras=())


class LaneKeeper:
    """Steers against CTE and heading error, holds a speed; counts what the runner tells it."""

    def __init__(self, speed_mph: float = 20.0) -> None:
        self.speed_mph = speed_mph
        self.resets = 0
        self.interventions: list[float] = []  # speed after each intervention

    def reset(self) -> None:
        self.resets += 1

    def act(self, obs) -> Controls:
        steering = -0.15 * obs.cte_m + 1.2 * obs.heading_error_rad
        steering -= 2.7 * obs.curvature_per_m / math.tan(math.radians(25))
        throttle = 0.3 * (self.speed_mph - obs.speed_mph)
        return Controls(steering=float(np.clip(steering, -1, 1)),
                        throttle=float(np.clip(throttle, -1, 1)))

    def intervened(self, obs) -> None:
        self.interventions.append(obs.speed_mph)


class Swerver(LaneKeeper):
    """Keeps the lane, but swerves right for a second every ``period_s``: it leaves the road."""

    def __init__(self, speed_mph: float = 20.0, period_s: float = 8.0) -> None:
        super().__init__(speed_mph)
        self.period_s = period_s

    def act(self, obs) -> Controls:
        controls = super().act(obs)
        if obs.time_s % self.period_s > self.period_s - 1.0:
            return Controls(steering=0.8, throttle=controls.throttle)
        return controls


class Parked:
    """Never moves."""

    def reset(self) -> None:
        pass

    def act(self, obs) -> Controls:
        return Controls(steering=0.0, throttle=0.0, brake=1.0)

    def intervened(self, obs) -> None:
        pass


def test_a_clean_lap_stops_the_episode_with_laps():
    with Simulator("lake", STATE_ONLY) as sim:
        episode = drive(Episode(sim, EpisodeRules(laps=1, set_speed_mph=20.0)), LaneKeeper(20.0))
        assert episode.stopped == Stop.LAPS
        trace = episode.trace
        assert trace.laps_completed == 1 and trace.off_road == [] and not trace.timed_out
        summary = trace.summary()
        assert summary["stopped"] == "laps" and summary["laps_completed"] == 1
        assert summary["distance_m"] == pytest.approx(sim.track.length_m, rel=0.02)
        assert summary["autonomy_pct"] == 100.0
        assert len(trace.time_s) == round(summary["elapsed_s"] * 15)


def test_leaving_the_road_is_an_intervention_at_the_set_speed():
    driver = Swerver(speed_mph=20.0)
    steps = []
    with Simulator("lake", STATE_ONLY) as sim:
        rules = EpisodeRules(laps=1, set_speed_mph=12.0, max_seconds=30.0)
        episode = drive(Episode(sim, rules), driver, on_step=steps.append)
    assert episode.stopped == Stop.SECONDS
    events = [step for step in steps if step.events]
    assert len(events) == episode.interventions == len(episode.trace.off_road) >= 2
    for step in events:
        assert step.intervened and step.observed.off_road
        (event,) = step.events
        assert abs(event.cte_m) > 2.0  # a tyre was off the 8 m road
    # Back on the centreline, heading along the road, at the set speed; the driver was told.
    assert driver.interventions == pytest.approx([12.0] * len(events))
    after = [steps[steps.index(step) + 1].seen for step in events]
    for obs in after:
        assert abs(obs.cte_m) < 0.05 and abs(obs.heading_error_rad) < 0.05
        assert obs.speed_mph == pytest.approx(12.0) and not obs.off_road
    summary = episode.trace.summary()
    assert summary["interventions"] == len(events) and summary["laps_completed"] == 0
    assert summary["autonomy_pct"] == pytest.approx((1 - len(events) * 6 / 30) * 100, abs=0.01)


def test_continue_counts_off_road_events_without_intervening():
    steps = []
    with Simulator("lake", STATE_ONLY) as sim:
        rules = EpisodeRules(laps=1, off_road="continue", max_off_road_events=2)
        episode = drive(Episode(sim, rules), Swerver(speed_mph=20.0), on_step=steps.append)
    assert episode.stopped == Stop.OFF_ROAD
    assert episode.interventions == 0 and not any(step.intervened for step in steps)
    assert episode.observation.off_road_events == 2
    # The car went on from where it was: some steps after the first event are still off road.
    first = next(i for i, step in enumerate(steps) if step.events)
    assert steps[first + 1].seen.off_road


def test_the_time_limit_stops_a_car_that_does_not_go_round():
    with Simulator("lake", STATE_ONLY) as sim:
        rules = EpisodeRules(laps=2, set_speed_mph=30.0, time_limit_factor=0.05)
        episode = Episode(sim, rules)
        limit = time_limit_s(sim.track.length_m, 2, 30.0, factor=0.05)
        assert episode.time_limit_s == pytest.approx(limit)
        assert limit == pytest.approx(0.05 * 2 * sim.track.length_m / (30 * MPH_TO_MPS) + 30)
        drive(episode, Parked())
    assert episode.stopped == Stop.TIME_LIMIT
    assert episode.trace.timed_out and episode.trace.summary()["stopped"] == "time_limit"
    assert episode.observation.time_s == pytest.approx(math.ceil(limit * 15) / 15)


def test_open_ended_rules_have_no_time_limit():
    assert EpisodeRules(laps=None, set_speed_mph=0.0).time_limit_s(1000.0) is None
    assert EpisodeRules(laps=1, set_speed_mph=0.0).time_limit_s(1000.0) is None
    assert EpisodeRules(laps=3, set_speed_mph=15.0).time_limit_s(1000.0) == pytest.approx(
        2.5 * 3 * 1000.0 / (15 * MPH_TO_MPS) + 30)


@pytest.mark.parametrize("values, field", [
    ({"set_speed_mph": float("nan")}, "set_speed_mph"),
    ({"set_speed_mph": -5.0}, "set_speed_mph"),
    ({"laps": 0}, "laps"),
    ({"off_road": "ignore"}, "off_road"),
    ({"max_seconds": float("inf")}, "max_seconds"),
    ({"max_seconds": 0.0}, "max_seconds"),
    ({"max_off_road_events": 0}, "max_off_road_events"),
    ({"time_limit_factor": 0.0}, "time_limit_factor"),
])
def test_bad_rules_are_refused_naming_the_field(values, field):
    with pytest.raises(ValueError, match=field):
        EpisodeRules(**values)


def test_a_stopped_episode_does_not_step_until_reset():
    with Simulator("lake", STATE_ONLY) as sim:
        episode = Episode(sim, EpisodeRules(max_seconds=0.2))
        with pytest.raises(RuntimeError, match="reset"):
            episode.observation  # noqa: B018
        drive(episode, Parked())
        assert episode.stopped == Stop.SECONDS and len(episode.trace.time_s) == 3
        with pytest.raises(RuntimeError, match="stopped"):
            episode.step(Controls())
        episode.reset()
        assert not episode.done and episode.trace.time_s == []


class Recording:
    """A batched driver that remembers which cars it was asked about, per call."""

    def __init__(self, speeds_mph) -> None:
        self.keepers = [LaneKeeper(speed) for speed in speeds_mph]
        self.calls: list[tuple[int, ...]] = []

    def reset(self, car: int) -> None:
        self.keepers[car].reset()

    def act(self, cars, observations):
        self.calls.append(tuple(cars))
        return [self.keepers[car].act(obs) for car, obs in zip(cars, observations, strict=True)]

    def intervened(self, car: int, obs) -> None:
        self.keepers[car].intervened(obs)


def test_lock_step_drives_every_active_car_per_call_and_matches_driving_alone():
    seconds = (2.0, 3.0)
    with Simulator("lake", STATE_ONLY) as a, Simulator("gen:3", STATE_ONLY) as b:
        episodes = [Episode(sim, EpisodeRules(set_speed_mph=speed, max_seconds=limit))
                    for sim, speed, limit in zip((a, b), (15.0, 25.0), seconds, strict=True)]
        driver = Recording([15.0, 25.0])
        Runner(episodes, driver).run()
        together = [episode.trace.summary() for episode in episodes]
        assert driver.calls == [(0, 1)] * 30 + [(1,)] * 15  # car 0 stopped after 2 s
        assert [keeper.resets for keeper in driver.keepers] == [1, 1]
        alone = []
        for sim, speed, limit in zip((a, b), (15.0, 25.0), seconds, strict=True):
            episode = drive(Episode(sim, EpisodeRules(set_speed_mph=speed, max_seconds=limit)),
                            LaneKeeper(speed))
            alone.append(episode.trace.summary())
    assert together == alone  # bit for bit: the runner adds nothing of its own


class Threaded(Recording):
    """A :class:`Recording` that also notes the thread each call ran on."""

    def __init__(self, keepers) -> None:
        self.keepers = keepers
        self.calls = []
        self.threads: list[str] = []

    def act(self, cars, observations):
        import threading

        self.threads.append(threading.current_thread().name)
        return super().act(cars, observations)


def test_overlap_decides_for_half_the_cars_on_a_helper_thread_and_drives_the_same():
    # Four cars: two swerve off the road now and then (interventions), and they stop at
    # different times, so the halves shrink and one empties before the end.
    limits = (3.0, 2.0, 4.0, 1.0)
    kinds = (Swerver, LaneKeeper, Swerver, LaneKeeper)

    def run(overlap: bool):
        sims = [Simulator("gen:3", STATE_ONLY) for _ in limits]
        try:
            episodes = [Episode(sim, EpisodeRules(set_speed_mph=20.0, max_seconds=limit))
                        for sim, limit in zip(sims, limits, strict=True)]
            driver = Threaded([kind(20.0, period_s=1.5) if kind is Swerver else kind(20.0)
                               for kind in kinds])
            labeller = Recording([20.0] * 4)
            steps = []
            Runner(episodes, driver, labeller=labeller, overlap=overlap).run(steps.append)
            return ([episode.trace.summary() for episode in episodes], driver, steps,
                    [episode.interventions for episode in episodes])
        finally:
            for sim in sims:
                sim.close()

    plain, plain_driver, plain_steps, plain_interventions = run(False)
    overlapped, driver, steps, interventions = run(True)
    assert overlapped == plain  # every car drove exactly as without overlap
    assert interventions == plain_interventions and interventions[0] > 0 and interventions[2] > 0
    assert [(s.car, s.seen.time_s, s.decision, s.label.controls) for s in steps] == \
        [(s.car, s.seen.time_s, s.decision, s.label.controls) for s in plain_steps]
    assert [keeper.interventions for keeper in driver.keepers] == \
        [keeper.interventions for keeper in plain_driver.keepers]
    # Each call decides for one half (even or odd cars); the odd half on the helper thread.
    assert all(len({car % 2 for car in call}) == 1 for call in driver.calls)
    helper = [thread for call, thread in zip(driver.calls, driver.threads, strict=True)
              if call[0] % 2 == 1]
    assert helper and all(name.startswith("runner-decide") for name in helper)
    assert set(plain_driver.threads) == {"MainThread"}


class Labeller:
    """Labels every step with a hard left turn and its own count."""

    def __init__(self) -> None:
        self.seen: list[float] = []

    def reset(self) -> None:
        pass

    def act(self, obs) -> Decision:
        self.seen.append(obs.time_s)
        return Decision(controls=Controls(steering=-1.0, throttle=1.0),
                        steering_label=-0.5, detail=len(self.seen))

    def intervened(self, obs) -> None:
        pass


def test_a_labeller_labels_every_step_without_steering():
    labeller = Labeller()
    with Simulator("lake", STATE_ONLY) as sim:
        labelled = []
        drive(Episode(sim, EpisodeRules(max_seconds=2.0)), LaneKeeper(), labeller=labeller,
              on_step=labelled.append)
        plain = []
        drive(Episode(sim, EpisodeRules(max_seconds=2.0)), LaneKeeper(), on_step=plain.append)
    assert len(labelled) == len(plain) == 30
    for with_label, without in zip(labelled, plain, strict=True):
        assert with_label.decision == without.decision  # the car drove as without a labeller
        assert with_label.observed.x_m == without.observed.x_m
        assert without.label is None
        assert with_label.label.label == -0.5 and with_label.label.controls.steering == -1.0
    # Asked once per step, about the observation the driver saw.
    assert labeller.seen == [step.seen.time_s for step in labelled]
    assert [step.label.detail for step in labelled] == list(range(1, 31))


def test_decisions_label_with_the_applied_steering_unless_told():
    assert Decision(Controls(steering=0.25)).label == 0.25
    assert Decision(Controls(steering=0.25), steering_label=0.1).label == 0.1


def test_per_car_drivers_and_wrong_answers():
    with Simulator("lake", STATE_ONLY) as sim:
        episode = Episode(sim, EpisodeRules(max_seconds=1.0))

        class Silent(Parked):
            def act(self, obs):
                return "left"

        with pytest.raises(TypeError, match="Decision or Controls"):
            Runner([episode], PerCar([Silent()])).step()
    with pytest.raises(ValueError, match="at least one episode"):
        Runner([], PerCar([]))


def test_cars_stepped_phase_by_phase_on_one_scene_see_what_they_see_alone():
    """The runner moves every car, then draws every car's frame, then finishes every car's step.
    With cameras on a shared scene (one rig draws all the cars in turn), each car's frames,
    interventions and trace are still exactly what it gets when driven alone on its own scene."""
    from clonedrive.sim.camera_pool import CameraPool

    config = SimConfig(cameras=("center",), image_width=64, image_height=32)
    limits = (2.0, 1.4, 1.8)
    options = ({"s_m": 0.0, "speed_mph": 20.0}, {"s_m": 30.0, "speed_mph": 20.0},
               {"s_m": 60.0, "offset_m": 1.0, "speed_mph": 20.0})

    def keeper(car: int):
        return Swerver(20.0, period_s=1.2) if car != 1 else LaneKeeper(20.0)

    def run_together():
        frames: dict[int, list] = {car: [] for car in range(len(limits))}
        with CameraPool() as pool:
            sims = [Simulator("lake", config, pool=pool) for _ in limits]
            try:
                episodes = [Episode(sim, EpisodeRules(set_speed_mph=20.0, max_seconds=limit),
                                    options=option)
                            for sim, limit, option in zip(sims, limits, options, strict=True)]
                Runner(episodes, PerCar([keeper(car) for car in range(len(limits))])).run(
                    lambda step: frames[step.car].append(step.observed.images["center"]))
                assert pool.scenes == 1
                return frames, [episode.trace.summary() for episode in episodes], \
                    [episode.interventions for episode in episodes]
            finally:
                for sim in sims:
                    sim.close()

    frames, summaries, interventions = run_together()
    assert interventions[0] > 0  # the swervers leave the road: interventions render too
    for car, (limit, option) in enumerate(zip(limits, options, strict=True)):
        steps: list = []
        with Simulator("lake", config) as sim:
            episode = Episode(sim, EpisodeRules(set_speed_mph=20.0, max_seconds=limit),
                              options=option)
            drive(episode, keeper(car), on_step=steps.append)
            alone = [step.observed.images["center"] for step in steps]
            assert episode.trace.summary() == summaries[car]
            assert episode.interventions == interventions[car]
        assert len(alone) == len(frames[car]) == round(limit * 15)
        assert all(np.array_equal(a, b) for a, b in zip(alone, frames[car], strict=True))


def test_a_step_in_parts_is_the_step_and_the_parts_keep_their_order():
    with Simulator("lake", STATE_ONLY) as whole, Simulator("lake", STATE_ONLY) as parts:
        whole.reset(seed=0)
        parts.reset(seed=0)
        controls = Controls(steering=0.1, throttle=0.5)
        with pytest.raises(RuntimeError, match="advance"):
            parts.render_advanced()
        parts.advance(controls)
        with pytest.raises(RuntimeError, match="already advanced"):
            parts.advance(controls)
        with pytest.raises(RuntimeError, match="middle of a step"):
            parts.intervene(20.0)
        assert parts.observation.time_s == 0.0  # the observation waits for the finish
        assert parts.finish_step() == whole.step(controls)
        with pytest.raises(RuntimeError, match="advance"):
            parts.finish_step()
    episode = Episode(Simulator("lake", STATE_ONLY), EpisodeRules(max_seconds=1.0))
    try:
        episode.reset()
        with pytest.raises(RuntimeError, match="begin"):
            episode.finish()
        episode.begin(Controls(throttle=0.3))
        with pytest.raises(RuntimeError, match="begun already"):
            episode.begin(Controls(throttle=0.3))
        assert episode.finish().observed.time_s == pytest.approx(1 / 15)
    finally:
        episode.sim.close()
