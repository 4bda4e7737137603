"""The expert policy, state-only (no rendering): it drives every track, its styles put the car
where they say, its labels are clean under noise, and it steers smoothly."""

import math

import numpy as np
import pytest

from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy
from clonedrive.sim.simulator import SimConfig, Simulator
from clonedrive.world.catalog import load_track

STATE_ONLY = SimConfig(cameras=())
STEP_S = 1.0 / 15.0


def drive(track_name, *, laps=1, seconds=None, seed=0, **expert_options):
    """Drive the expert; returns (observations before each step, actions, final observation)."""
    track = load_track(track_name)
    config = ExpertConfig(**expert_options)
    expert = ExpertPolicy(track, config, np.random.default_rng(seed))
    observations, actions = [], []
    with Simulator(track, STATE_ONLY) as sim:
        obs, _ = sim.reset(seed=seed, options={"reverse": config.reverse})
        limit_s = seconds if seconds is not None else 600.0
        while sim.laps_started < laps and obs.time_s < limit_s - 1e-9:
            action = expert.act(obs)
            observations.append(obs)
            actions.append(action)
            obs, _ = sim.step(action.controls_applied)
    return observations, actions, obs


TRACKS = [("lake", False), ("lake", True), ("mountain", False), ("mountain", True)]
TRACKS += [(f"gen:{seed}", False) for seed in range(20)]


@pytest.mark.parametrize(("track_name", "reverse"), TRACKS,
                         ids=[f"{name}{'-reverse' if rev else ''}" for name, rev in TRACKS])
def test_drives_a_lap_at_30_mph_without_leaving_the_road(track_name, reverse):
    observations, actions, final = drive(track_name, speed_mph=30.0, reverse=reverse)
    assert final.off_road_events == 0
    assert final.laps == 1
    speeds = np.array([obs.speed_mph for obs in observations])
    assert speeds.max() <= 30.5
    assert np.abs([obs.cte_m for obs in observations]).max() < 1.5


def test_slows_for_a_hairpin_and_speeds_up_on_straights():
    track = load_track("mountain")
    expert = ExpertPolicy(track, ExpertConfig(speed_mph=30.0))
    tightest = float(track.s[np.argmax(np.abs(track.curvature_table))])
    radius = 1.0 / float(np.abs(track.curvature_table).max())
    # v^2 / R <= 0.5 g at the tightest point, and the set speed is a maximum.
    assert expert.speed_limit_mph(tightest) * 0.44704 <= math.sqrt(0.5 * 9.81 * radius) + 1e-6
    assert max(expert.speed_limit_mph(s) for s in track.s) == pytest.approx(30.0)
    observations, _, _ = drive("mountain", seconds=120.0, speed_mph=30.0)
    fast = [obs.speed_mph for obs in observations if abs(obs.curvature_per_m) < 1 / 500]
    tight = [obs.speed_mph for obs in observations if abs(obs.curvature_per_m) > 1 / 15]
    assert tight and max(tight) < 20.0
    assert max(fast) > 28.0


def test_without_noise_the_label_is_the_applied_steering():
    _, actions, _ = drive("lake", seconds=30.0, noise=0.0)
    for action in actions:
        assert action.label_steering == action.controls_applied.steering
        assert action.noise == 0.0


def test_with_noise_the_label_is_the_clean_command_for_the_state():
    observations, actions, final = drive("lake", seconds=60.0, speed_mph=20.0, noise=0.2, seed=3)
    assert final.off_road_events == 0
    applied = np.array([action.controls_applied.steering for action in actions])
    labels = np.array([action.label_steering for action in actions])
    assert np.mean(np.abs(applied - labels) > 0.01) > 0.5  # the car is really perturbed
    # A noise-free twin shown the same states gives exactly the same labels.
    track = load_track("lake")
    twin = ExpertPolicy(track, ExpertConfig(speed_mph=20.0, noise=0.0), np.random.default_rng(3))
    twin_labels = np.array([twin.act(obs).label_steering for obs in observations])
    np.testing.assert_array_equal(twin_labels, labels)


def test_noise_moves_the_car_off_the_line_and_it_recovers():
    clean, _, _ = drive("lake", seconds=60.0, speed_mph=20.0, noise=0.0)
    noisy, _, final = drive("lake", seconds=60.0, speed_mph=20.0, noise=0.3, seed=1)
    assert final.off_road_events == 0
    assert np.std([obs.cte_m for obs in noisy]) > 2 * np.std([obs.cte_m for obs in clean])


def test_same_seed_same_drive():
    _, first, _ = drive("lake", seconds=20.0, noise=0.2, seed=5, style="weave")
    _, second, _ = drive("lake", seconds=20.0, noise=0.2, seed=5, style="weave")
    assert first == second


@pytest.mark.parametrize("reverse", [False, True])
def test_left_and_right_styles_keep_to_their_side(reverse):
    for style, sign in (("left", -1.0), ("right", 1.0)):
        observations, actions, final = drive("lake", speed_mph=30.0, style=style,
                                             reverse=reverse)
        assert final.off_road_events == 0 and final.laps == 1
        settled = [obs.cte_m for obs in observations if obs.time_s > 5.0]
        assert all(sign * cte > 0 for cte in settled)  # always on that side of centre
        half_usable = 0.5 * 8.0 - 0.9
        assert np.median(np.abs(settled)) == pytest.approx(0.6 * half_usable, abs=0.3)
        assert all(sign * action.target_offset_m > 0 for action in actions)


def test_weave_crosses_the_centre_line():
    observations, _, final = drive("lake", speed_mph=30.0, style="weave")
    assert final.off_road_events == 0 and final.laps == 1
    cte = np.array([obs.cte_m for obs in observations if obs.time_s > 5.0])
    crossings = np.count_nonzero(np.diff(np.sign(cte)) != 0)
    assert crossings >= 8  # a 1090 m lap at 160 m per cycle crosses about 13 times
    assert cte.min() < -1.2 and cte.max() > 1.2


def test_turns_marks_only_curved_samples():
    threshold = 1.0 / 80.0
    observations, actions, final = drive("lake", speed_mph=30.0, style="turns",
                                         turn_curvature_per_m=threshold)
    assert final.off_road_events == 0
    marked = np.array([action.record for action in actions])
    curvature = np.abs([obs.curvature_per_m for obs in observations])
    assert 0.1 < marked.mean() < 0.9
    assert marked[curvature > threshold].all()
    # A mark away from the curve itself is at most 3 m (plus one 0.5 m grid step) from it.
    track = load_track("lake")
    nearby = np.array([np.abs(track.curvature(obs.s_m + np.linspace(-4.0, 4.0, 33))).max()
                       for obs in observations])
    assert not marked[nearby < threshold].any()
    assert np.mean(curvature[marked] > threshold) > 0.8
    # Other styles record every sample.
    _, center_actions, _ = drive("lake", seconds=10.0)
    assert all(action.record for action in center_actions)


def test_steering_is_smooth():
    config = ExpertConfig()
    max_step = config.steering_rate_per_s * STEP_S
    _, actions, _ = drive("mountain", seconds=120.0, speed_mph=30.0, noise=0.1, seed=2)
    labels = np.array([action.label_steering for action in actions])
    applied = np.array([action.controls_applied.steering for action in actions])
    assert np.abs(np.diff(labels)).max() <= max_step + 1e-12
    assert np.abs(np.diff(applied)).max() < 0.25
    # Like a human with a wheel: mostly small changes, never keyboard-style +/-1 jumps.
    assert np.percentile(np.abs(np.diff(labels)), 95) < 0.03
    assert np.abs(labels).max() < 0.9


def test_config_is_validated():
    with pytest.raises(ValueError, match="style"):
        ExpertConfig(style="zigzag")
    with pytest.raises(ValueError, match="noise"):
        ExpertConfig(noise=-0.1)
    with pytest.raises(ValueError, match="offset_fraction"):
        ExpertConfig(offset_fraction=1.5)
