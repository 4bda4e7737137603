import math
from dataclasses import replace

import numpy as np
import pytest

from clonedrive.world.vehicle import (
    AIR_DENSITY_KGPM3,
    GRAVITY_MPS2,
    MPH_TO_MPS,
    Controls,
    RoadContact,
    VehicleParams,
    VehicleState,
    hold_on_slope_throttle,
    integrate,
    step,
)

PARAMS = VehicleParams()
DT = 1 / 150


def run(state, controls, seconds, road=None, params=PARAMS):
    states = [state]
    for _ in range(int(round(seconds / DT))):
        state = step(state, controls, DT, params, road)
        states.append(state)
    return states


def test_low_speed_circle_radius_is_wheelbase_over_tan_delta():
    steering = 0.6
    delta = steering * PARAMS.max_wheel_angle_rad
    expected = PARAMS.wheelbase_m / math.tan(delta)
    # Creep at 1.5 m/s (kinematic regime); throttle balances rolling resistance.
    throttle = PARAMS.c_rr * PARAMS.m * GRAVITY_MPS2 / PARAMS.max_drive_force_n
    states = run(VehicleState(v_x_mps=1.5), Controls(steering=steering, throttle=throttle), 30)
    xy = np.array([(s.x_m, s.y_m) for s in states[1500:]])
    # Fit a circle (algebraic least squares) to the path of the CG.
    a = np.column_stack([2 * xy, np.ones(len(xy))])
    cx, cy, c = np.linalg.lstsq(a, (xy**2).sum(axis=1), rcond=None)[0]
    radius_cg = math.sqrt(c + cx**2 + cy**2)
    # The CG is l_r ahead of the rear axle, whose radius is L / tan(delta).
    radius_rear = math.sqrt(radius_cg**2 - PARAMS.l_r**2)
    assert radius_rear == pytest.approx(expected, rel=0.01)
    assert states[-1].r_radps < 0  # steering right (+) turns clockwise


def test_full_throttle_reaches_and_holds_top_speed():
    states = run(VehicleState(), Controls(throttle=1.0), 30)
    speeds = np.array([s.v_x_mps for s in states])
    assert speeds.max() <= PARAMS.top_speed_mps + 1e-9
    assert speeds[-1] == pytest.approx(PARAMS.top_speed_mps, abs=0.05)
    # Initial acceleration is drive force over mass less rolling resistance (drag ~ 0 at rest).
    assert (speeds[15] - speeds[0]) / (15 * DT) == pytest.approx(
        PARAMS.max_drive_force_n / PARAMS.m - PARAMS.c_rr * GRAVITY_MPS2, rel=0.01)


def test_coast_down_matches_closed_form():
    v0 = PARAMS.top_speed_mps
    states = run(VehicleState(v_x_mps=v0), Controls(), 10)
    a = PARAMS.c_rr * GRAVITY_MPS2
    b = 0.5 * AIR_DENSITY_KGPM3 * PARAMS.c_d_a_m2 / PARAMS.m
    t = 10.0
    expected = math.sqrt(a / b) * math.tan(math.atan(v0 * math.sqrt(b / a)) - math.sqrt(a * b) * t)
    assert states[-1].v_x_mps == pytest.approx(expected, rel=0.01)


def test_throttle_holds_the_car_on_a_slope_and_gravity_acts_without_it():
    road = RoadContact(grade=0.10)
    held = run(VehicleState(), Controls(throttle=hold_on_slope_throttle(0.10, PARAMS)), 10, road)
    assert abs(held[-1].v_x_mps) < 1e-6 and abs(held[-1].x_m) < 1e-6
    rolled = run(VehicleState(), Controls(), 2, road)
    assert rolled[-1].v_x_mps < -0.5  # rolls back downhill
    uphill = run(VehicleState(v_x_mps=10), Controls(), 3, road)[-1].v_x_mps
    flat = run(VehicleState(v_x_mps=10), Controls(), 3)[-1].v_x_mps
    downhill = run(VehicleState(v_x_mps=10), Controls(), 3, RoadContact(grade=-0.10))[-1].v_x_mps
    assert uphill < flat < downhill


def test_no_nans_at_rest_with_any_controls():
    for controls in (Controls(), Controls(steering=1.0), Controls(steering=-1.0, brake=1.0),
                     Controls(steering=float("nan"), throttle=float("inf"))):
        state = run(VehicleState(), controls, 3)[-1]
        values = [state.x_m, state.y_m, state.yaw_rad, state.v_x_mps, state.v_y_mps, state.r_radps]
        assert all(math.isfinite(v) for v in values)
    at_rest = run(VehicleState(), Controls(steering=1.0), 3)[-1]
    assert at_rest.speed_mps == pytest.approx(0, abs=1e-6)


def test_brakes_stop_without_reversing_and_negative_throttle_reverses_when_slow():
    braked = run(VehicleState(v_x_mps=10), Controls(brake=1.0), 5)
    assert min(s.v_x_mps for s in braked) >= 0.0
    assert braked[-1].v_x_mps == pytest.approx(0.0, abs=1e-6)
    slowed = run(VehicleState(v_x_mps=10), Controls(throttle=-1.0), 0.5)
    assert slowed[-1].v_x_mps < 10 - 0.5 * PARAMS.max_brake_force_n / PARAMS.m * 0.9
    reversing = run(VehicleState(v_x_mps=1.0), Controls(throttle=-1.0), 5)
    assert reversing[-1].v_x_mps < 0
    assert reversing[-1].v_x_mps >= -PARAMS.max_reverse_speed_mps - 0.05


def test_dynamic_regime_understeers_and_grip_drops_off_road():
    # At speed, slip makes the turn wider than the kinematic radius for this car (C_r > C_f).
    steering = 0.2
    speed = 12.0
    road = RoadContact()
    throttle = 0.3
    states = run(VehicleState(v_x_mps=speed), Controls(steering=steering, throttle=throttle), 8,
                 road)
    s = states[-1]
    kinematic_r = s.v_x_mps * math.tan(steering * PARAMS.max_wheel_angle_rad) / PARAMS.wheelbase_m
    assert 0.5 * kinematic_r < abs(s.r_radps) < kinematic_r
    # Off the road the car cannot take a turn that it takes on the road.
    hard = Controls(steering=0.6, throttle=0.5)
    on = run(VehicleState(v_x_mps=13), hard, 3)[-1]
    off = run(VehicleState(v_x_mps=13), hard, 3, RoadContact(front_on_road=0, rear_on_road=0))[-1]
    assert abs(off.r_radps) < abs(on.r_radps)


def test_top_speed_is_30_mph():
    assert replace(PARAMS).top_speed_mps == pytest.approx(30 * MPH_TO_MPS)


def test_controls_are_clipped_into_range_and_non_finite_values_become_zero():
    inside = Controls(steering=-1.0, throttle=0.3, brake=1.0)
    assert inside.clipped() == inside
    assert Controls(steering=1.7, throttle=-3.0, brake=-0.2).clipped() == Controls(1.0, -1.0, 0.0)
    assert Controls(steering=float("nan"), throttle=float("inf"),
                    brake=float("-inf")).clipped() == Controls(0.0, 0.0, 0.0)
    assert Controls(steering=0.5, throttle=float("nan")).clipped() == Controls(0.5, 0.0, 0.0)


# Reversing, at rest, kinematic, blended, dynamic, at the top speed.
@pytest.mark.parametrize("v_x", [-1.5, 0.0, 1.0, 3.5, 9.0, 13.4])
def test_integrate_gives_the_numbers_of_step_chained(v_x):
    """A control period in one call (the simulator's 10 physics steps) equals step() called 10
    times, to the last bit, in every regime: braking through zero, reversing, the top-speed
    governor, slopes, off the road, NaN steering."""
    start = VehicleState(x_m=12.5, y_m=-40.0, yaw_rad=3.1, v_x_mps=v_x, v_y_mps=0.2 * v_x / 9,
                         r_radps=-0.05)
    controls = [Controls(), Controls(steering=0.4, throttle=0.6),
                Controls(steering=-1.0, brake=1.0), Controls(steering=0.2, throttle=-1.0),
                Controls(steering=float("nan"), throttle=1.0),
                Controls(steering=-0.7, throttle=0.3, brake=0.2)]
    roads = [RoadContact(), RoadContact(grade=0.12, front_on_road=0.5, rear_on_road=1.0),
             RoadContact(grade=-0.08, front_on_road=0.0, rear_on_road=0.0)]
    for control in controls:
        for road in roads:
            chained = start
            for _ in range(10):
                chained = step(chained, control, DT, PARAMS, road)
            assert integrate(start, control, DT, PARAMS, road, 10) == chained, (control, road)


def test_integrate_refuses_fewer_than_one_step():
    with pytest.raises(ValueError, match="substeps"):
        integrate(VehicleState(), Controls(), DT, PARAMS, None, 0)
