import math

import numpy as np
import pytest

from clonedrive.sim.simulator import Controls, SimConfig, Simulator

STATE_ONLY = SimConfig(cameras=())


def lane_keeper(obs, speed_mph=15.0):
    """A plain feedback law for tests: steer against CTE and heading error, hold a speed."""
    steering = -0.15 * obs.cte_m + 1.2 * obs.heading_error_rad
    steering -= 2.7 * obs.curvature_per_m / math.tan(math.radians(25))
    throttle = 0.3 * (speed_mph - obs.speed_mph)
    return Controls(steering=float(np.clip(steering, -1, 1)),
                    throttle=float(np.clip(throttle, -1, 1)))


def rollout(sim, steps, seed=0, options=None, policy=lane_keeper):
    obs, _ = sim.reset(seed=seed, options=options)
    trace = [obs]
    for _ in range(steps):
        obs, _ = sim.step(policy(obs))
        trace.append(obs)
    return trace


def test_same_seed_same_controls_is_bit_identical():
    with Simulator("mountain", STATE_ONLY) as a, Simulator("mountain", STATE_ONLY) as b:
        trace_a = rollout(a, 300)
        trace_b = rollout(b, 300)
    for oa, ob in zip(trace_a, trace_b, strict=True):
        assert (oa.x_m, oa.y_m, oa.yaw_rad, oa.speed_mph, oa.cte_m) == \
               (ob.x_m, ob.y_m, ob.yaw_rad, ob.speed_mph, ob.cte_m)


def test_a_clean_lap_is_counted_once_the_start_line_is_crossed():
    with Simulator("lake", STATE_ONLY) as sim:
        obs, _ = sim.reset(seed=0)
        lap_steps = []
        for i in range(2500):
            obs, info = sim.step(lane_keeper(obs, 20.0))
            if info["lap_completed"]:
                lap_steps.append(i)
            if obs.laps == 1:
                break
        assert obs.laps == 1 and obs.off_road_events == 0
        assert obs.distance_m == pytest.approx(sim.track.length_m, rel=0.02)
        assert len(lap_steps) == 1
        assert obs.time_s == pytest.approx((lap_steps[0] + 1) / 15.0)


def test_leaving_the_road_is_an_event_with_where_and_spoils_the_lap():
    with Simulator("lake", STATE_ONLY) as sim:
        obs, _ = sim.reset(seed=0, options={"s_m": 300.0, "speed_mph": 15.0})
        events = []
        for _ in range(120):
            obs, info = sim.step(Controls(steering=0.5, throttle=0.2))
            events += info["events"]
        assert obs.off_road_events == len(events) >= 1
        first = events[0]
        assert abs(first.cte_m) > sim.track.width_at(first.s_m) / 2 - 2.0  # a tyre, not the CG
        assert first.s_m > 300.0 and first.lap == 0
        # An intervention puts the car back on the centreline, heading along the road.
        obs = sim.intervene(speed_mph=10.0)
        assert abs(obs.cte_m) < 0.1 and abs(obs.heading_error_rad) < 0.05
        assert obs.speed_mph == pytest.approx(10.0) and not obs.off_road


def test_reverse_direction_measures_along_the_reversed_track():
    with Simulator("lake", STATE_ONLY) as sim:
        trace = rollout(sim, 200, options={"reverse": True})
        assert trace[0].heading_error_rad == pytest.approx(0.0, abs=1e-6)
        assert trace[-1].s_m > 50.0  # progress counts in the reversed driving direction
        assert trace[-1].off_road_events == 0
        assert abs(trace[-1].cte_m) < 1.0


def test_start_options_place_the_car():
    with Simulator("mountain", STATE_ONLY) as sim:
        obs, _ = sim.reset(options={"s_m": 500.0, "offset_m": 2.0, "speed_mph": 12.0})
        assert obs.s_m == pytest.approx(500.0, abs=0.3)
        assert obs.cte_m == pytest.approx(2.0, abs=0.05)
        assert obs.speed_mph == pytest.approx(12.0)
        with pytest.raises(ValueError, match="unknown reset option"):
            sim.reset(options={"lane": 1})


def test_car_follows_the_road_height_and_pitches_on_hills():
    with Simulator("mountain", STATE_ONLY) as sim:
        track = sim.track
        s = float(np.argmax(track.grade_table) * track.ds_m)
        obs, _ = sim.reset(options={"s_m": s})
        assert obs.z_m == pytest.approx(track.point(s)[2], abs=0.05)
        assert obs.pitch_rad == pytest.approx(math.atan(track.grade(s)), abs=0.01)
        assert obs.pitch_rad > 0.05
        obs, _ = sim.reset(options={"s_m": track.length_m - s, "reverse": True})
        assert obs.pitch_rad < -0.05  # the same climb driven the other way is a descent


def test_config_is_validated():
    with pytest.raises(ValueError, match="multiple of control_hz"):
        SimConfig(control_hz=15, physics_hz=100)
    with pytest.raises(ValueError, match="unknown camera"):
        SimConfig(cameras=("roof",))


def test_step_before_reset_is_a_clear_error():
    with Simulator("lake", STATE_ONLY) as sim:
        with pytest.raises(RuntimeError, match=r"step\(\) before reset\(\)"):
            sim.step(Controls())
        with pytest.raises(RuntimeError, match="before reset"):
            sim.intervene(10.0)
        sim.reset()
        obs, info = sim.step(Controls(throttle=1.0))
        assert obs.time_s == pytest.approx(1 / 15) and info["events"] == []
