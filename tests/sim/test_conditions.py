"""Driving conditions as data: families draw the same conditions for the same seed, held-out
families lie outside what training randomises, and each condition changes the rendered frame."""

import numpy as np
import pytest

from clonedrive.sim.conditions import FAMILIES, ConditionFamily, Conditions, jpeg_round_trip
from clonedrive.sim.randomization import RandomizationConfig
from clonedrive.sim.scenery import build_scenery
from clonedrive.sim.simulator import SimConfig, Simulator
from clonedrive.world.catalog import load_track


def test_a_family_draws_the_same_conditions_for_the_same_seed_within_its_ranges():
    dusk = FAMILIES["dusk"]
    assert dusk.sample(3) == dusk.sample(3)
    assert dusk.sample(3) != dusk.sample(4)
    for seed in range(20):
        c = dusk.sample(seed)
        assert 4.0 <= c.sun_elevation_deg <= 9.0 and c.shadows == 0.5
    latencies = {FAMILIES["latency"].sample(seed).latency_steps for seed in range(40)}
    assert latencies == {1, 2, 3}


def test_held_out_families_lie_outside_the_training_randomisation():
    training = RandomizationConfig()
    assert FAMILIES["clear"].held_out is False
    held_out = [f for f in FAMILIES.values() if f.held_out]
    assert len(held_out) >= 3
    for seed in range(10):
        dusk = FAMILIES["dusk"].sample(seed)
        assert dusk.sun_elevation_deg < training.sun_elevation_deg[0]
        assert FAMILIES["fog"].sample(seed).fog > training.fog_density_scale[1]
        assert FAMILIES["worn-road"].sample(seed).line in ("white", "faded-white")
        assert FAMILIES["sensor"].sample(seed).jpeg_quality < 75


def test_families_round_trip_and_bad_entries_name_the_field():
    for family in FAMILIES.values():
        again = ConditionFamily.from_dict(family.name, family.to_dict())
        assert again.sample(5) == family.sample(5)
    with pytest.raises(ValueError, match="unknown field 'rain'"):
        ConditionFamily.from_dict("x", {"rain": 1.0})
    with pytest.raises(ValueError, match="low <= high"):
        ConditionFamily.from_dict("x", {"fog": [3.0, 1.0]})
    with pytest.raises(ValueError, match="latency_steps must be a number in"):
        ConditionFamily.from_dict("x", {"latency_steps": [0, 9]})
    with pytest.raises(ValueError, match="line must be one of"):
        Conditions(line="pink")


def render(conditions, track="lake", *, scenery=False):
    config = SimConfig(cameras=("center",), image_width=96, image_height=48, scenery=scenery,
                       conditions=conditions)
    with Simulator(track, config) as sim:
        obs, _ = sim.reset(seed=0, options={"s_m": 40.0})
    return obs


def test_each_condition_changes_the_frame_and_none_changes_the_physics():
    clear = render(None)
    neutral = render(Conditions()).images["center"]
    # (a scene's edge pixels can differ with the buffers made earlier in the process: see
    # clonedrive.base.workers, which runs each batch of episodes in a fresh process)
    assert (neutral != clear.images["center"]).any(axis=2).mean() < 0.002
    frames = {name: render(FAMILIES[name].sample(1)) for name in
              ("dusk", "fog", "worn-road", "sensor")}
    base = clear.images["center"].astype(float)
    for name, obs in frames.items():
        assert np.abs(obs.images["center"].astype(float) - base).mean() > 2.0, name
        assert (obs.x_m, obs.y_m, obs.cte_m) == (clear.x_m, clear.y_m, clear.cte_m)
    assert frames["dusk"].images["center"].mean() < 0.8 * base.mean()
    # fog: the road ahead (rows below the horizon) fades into the fog's (horizon) colour
    horizon = np.array([170.0, 196.0, 222.0])
    rows = slice(18, 22)  # the road 30-100 m ahead
    fogged = np.abs(frames["fog"].images["center"][rows] - horizon).mean()
    assert fogged < 0.7 * np.abs(clear.images["center"][rows] - horizon).mean()


def test_vegetation_and_road_colour_change_the_scenery():
    track = load_track("lake")
    sparse = build_scenery(track, style=Conditions(vegetation=0.3).style("lake"))
    dense = build_scenery(track, style=Conditions(vegetation=2.5).style("lake"))
    assert dense.counts["trees"] > 2 * sparse.counts["trees"]
    darker = Conditions(road_brightness=0.5).style("lake")
    assert darker.road_rgb[0] == pytest.approx(0.5 * build_scenery(
        track, full=False).style.road_rgb[0])


def test_jpeg_round_trip_loses_detail_with_quality():
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (48, 96, 3), dtype=np.uint8)
    low = np.abs(jpeg_round_trip(image, 20).astype(int) - image).mean()
    high = np.abs(jpeg_round_trip(image, 95).astype(int) - image).mean()
    assert low > high > 0
