"""Vehicle dynamics: a single-track (bicycle) model with linear tyres, blended to the kinematic
model at low speed. Pure Python/NumPy: no rendering, no track imports.

Symbols follow the textbook single-track model (Rajamani, *Vehicle Dynamics and Control*, ch. 2):
``m`` mass [kg], ``I_z`` yaw inertia [kg m^2], ``l_f``/``l_r`` CG to front/rear axle [m],
``C_f``/``C_r`` axle cornering stiffness [N/rad]. State is in the body frame: ``v_x`` forward,
``v_y`` left [m/s], ``r`` yaw rate [rad/s]; pose in the world frame.

Controls follow the Udacity car: steering in [-1, 1] times a 25 deg maximum wheel angle, applied at
once; throttle in [-1, 1] (negative brakes, and reverses below 5 mph); an explicit brake in [0, 1];
top speed 30 mph.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from clonedrive.base.udacity_spec import MAX_WHEEL_ANGLE_DEG

MPH_TO_MPS = 0.44704
GRAVITY_MPS2 = 9.81
AIR_DENSITY_KGPM3 = 1.2


@dataclass(frozen=True)
class VehicleParams:
    """A mid-size sedan (about a Toyota Camry / VW Passat)."""

    m: float = 1500.0  #: mass [kg]
    I_z: float = 2250.0  #: yaw moment of inertia [kg m^2]
    l_f: float = 1.2  #: CG to front axle [m]
    l_r: float = 1.5  #: CG to rear axle [m]
    track_width_m: float = 1.55  #: distance between left and right tyres [m]
    C_f: float = 80_000.0  #: front axle cornering stiffness [N/rad]
    C_r: float = 90_000.0  #: rear axle cornering stiffness [N/rad]
    mu: float = 1.0  #: tyre-road friction coefficient on asphalt
    max_wheel_angle_deg: float = MAX_WHEEL_ANGLE_DEG
    top_speed_mps: float = 30.0 * MPH_TO_MPS
    max_reverse_speed_mps: float = 5.0 * MPH_TO_MPS
    reverse_below_mps: float = 5.0 * MPH_TO_MPS  #: negative throttle reverses below this speed
    max_drive_force_n: float = 4500.0  #: at full throttle (~0.3 g)
    max_brake_force_n: float = 12_000.0  #: at full brake (~0.8 g)
    c_rr: float = 0.015  #: rolling resistance coefficient on asphalt
    c_d_a_m2: float = 0.70  #: drag coefficient times frontal area [m^2]
    kinematic_below_mps: float = 2.0  #: pure kinematic model below this speed
    dynamic_above_mps: float = 5.0  #: pure dynamic model above this speed
    #: off the road (grass, dirt): grip and rolling resistance multipliers
    off_road_grip: float = 0.6
    off_road_rolling: float = 5.0

    @property
    def wheelbase_m(self) -> float:
        return self.l_f + self.l_r

    @property
    def max_wheel_angle_rad(self) -> float:
        return math.radians(self.max_wheel_angle_deg)


#: The rate the simulator integrates the car at [Hz] (its control period is several steps).
PHYSICS_HZ = 150.0

#: The car's top speed [mph]: a set speed above it cannot be held.
TOP_SPEED_MPH = round(VehicleParams.top_speed_mps / MPH_TO_MPS, 6)


def check_set_speed(value: object, name: str = "speed_mph") -> float:
    """``value`` as a set speed [mph] in (0, :data:`TOP_SPEED_MPH`], or ``ValueError`` naming
    ``name`` (NaN, infinity, booleans and text refused): the one speed check of every command."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or not 0.0 < value <= TOP_SPEED_MPH:
        raise ValueError(f"{name} must be a speed in (0, {TOP_SPEED_MPH:g}] mph (the car's top "
                         f"speed), got {value!r}")
    return float(value)


@dataclass(frozen=True)
class VehicleState:
    """Pose in the world frame and velocities in the body frame."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0  #: heading, counter-clockwise from +x
    v_x_mps: float = 0.0  #: forward speed (negative when reversing)
    v_y_mps: float = 0.0  #: lateral speed, + = left
    r_radps: float = 0.0  #: yaw rate, + = counter-clockwise
    wheel_angle_rad: float = 0.0  #: front wheel angle, + = left

    @property
    def speed_mps(self) -> float:
        return math.hypot(self.v_x_mps, self.v_y_mps)


@dataclass(frozen=True)
class Controls:
    """Driver commands in the Udacity simulator's units."""

    steering: float = 0.0  #: [-1, 1], + = right; times the maximum wheel angle
    throttle: float = 0.0  #: [-1, 1]; negative brakes, and reverses below 5 mph
    brake: float = 0.0  #: [0, 1]

    def clipped(self) -> Controls:
        steering, throttle, brake = self.steering, self.throttle, self.brake
        if -1.0 <= steering <= 1.0 and -1.0 <= throttle <= 1.0 and 0.0 <= brake <= 1.0:
            return self  # already in range (NaN fails every comparison): nothing to clip

        def clip(value: float, low: float, high: float) -> float:
            if not math.isfinite(value):
                return 0.0
            return min(max(value, low), high)

        return Controls(
            steering=clip(self.steering, -1.0, 1.0),
            throttle=clip(self.throttle, -1.0, 1.0),
            brake=clip(self.brake, 0.0, 1.0),
        )


@dataclass(frozen=True)
class RoadContact:
    """What the road under the car does to it during one step."""

    grade: float = 0.0  #: slope along the car's heading, dz/ds (+ = uphill)
    front_on_road: float = 1.0  #: fraction of front tyres on the road surface, 0..1
    rear_on_road: float = 1.0  #: fraction of rear tyres on the road surface, 0..1


def tyre_positions(state: VehicleState, params: VehicleParams) -> list[tuple[float, float]]:
    """World (x, y) of the four tyre contact points: front-left, front-right, rear-left,
    rear-right."""
    cos_yaw, sin_yaw = math.cos(state.yaw_rad), math.sin(state.yaw_rad)
    half = 0.5 * params.track_width_m
    points = []
    for forward, left in ((params.l_f, half), (params.l_f, -half),
                          (-params.l_r, half), (-params.l_r, -half)):
        points.append((state.x_m + forward * cos_yaw - left * sin_yaw,
                       state.y_m + forward * sin_yaw + left * cos_yaw))
    return points


def longitudinal_force(v_x: float, controls: Controls, params: VehicleParams) -> float:
    """Drive/brake force along the car [N] from throttle and brake (no resistances)."""
    throttle = controls.throttle
    force = 0.0
    if throttle >= 0.0:
        if v_x < params.top_speed_mps:  # the governor cuts drive at top speed
            force = throttle * params.max_drive_force_n
    elif v_x > params.reverse_below_mps:
        force = throttle * params.max_brake_force_n  # negative throttle brakes
    elif v_x > -params.max_reverse_speed_mps:
        force = throttle * params.max_drive_force_n  # and reverses at low speed
    if controls.brake > 0.0:
        force -= _smooth_sign(v_x) * controls.brake * params.max_brake_force_n
    return force


def _smooth_sign(v: float, width: float = 0.05) -> float:
    """sign(v), smoothed near zero so that braking and rolling resistance never reverse the car."""
    return math.tanh(v / width)


def step(state: VehicleState, controls: Controls, dt_s: float, params: VehicleParams,
         road: RoadContact | None = None) -> VehicleState:
    """Advance the car by ``dt_s`` seconds (semi-implicit Euler). ``controls`` are clipped;
    ``road`` defaults to level asphalt."""
    return integrate(state, controls, dt_s, params, road)


def integrate(state: VehicleState, controls: Controls, dt_s: float, params: VehicleParams,
              road: RoadContact | None = None, substeps: int = 1) -> VehicleState:
    """``substeps`` steps of ``dt_s`` seconds each under the same controls and road contact:
    the same numbers as :func:`step` called ``substeps`` times (every sum and product in the
    same order), with what stays the same over the steps worked out once and the state kept in
    plain floats in between (a control period of the simulator is 10 of them)."""
    if substeps < 1:
        raise ValueError(f"substeps must be at least 1, got {substeps}")
    controls = controls.clipped()
    road = road if road is not None else RoadContact()
    p = params
    throttle, brake = controls.throttle, controls.brake
    delta = -controls.steering * p.max_wheel_angle_rad  # steering + = right = negative angle
    grip_f = 1.0 - (1.0 - p.off_road_grip) * (1.0 - road.front_on_road)
    grip_r = 1.0 - (1.0 - p.off_road_grip) * (1.0 - road.rear_on_road)
    on_road = 0.5 * (road.front_on_road + road.rear_on_road)
    c_rr = p.c_rr * (1.0 + (p.off_road_rolling - 1.0) * (1.0 - on_road))
    cos_slope = 1.0 / math.sqrt(1.0 + road.grade * road.grade)
    sin_slope = road.grade * cos_slope
    normal_n = p.m * GRAVITY_MPS2 * cos_slope
    # Constant over the steps; each is the leading part of a product in the step below.
    mass, drag, gravity = p.m, 0.5 * AIR_DENSITY_KGPM3 * p.c_d_a_m2, p.m * GRAVITY_MPS2 * sin_slope
    wheelbase, l_f, l_r, yaw_inertia = p.wheelbase_m, p.l_f, p.l_r, p.I_z
    blend_low, blend_span = p.kinematic_below_mps, p.dynamic_above_mps - p.kinematic_below_mps
    cos_delta, tan_delta = math.cos(delta), math.tan(delta)
    load_f = normal_n * p.l_r / wheelbase
    load_r = normal_n * p.l_f / wheelbase
    stiffness_f, stiffness_r = p.C_f * grip_f, p.C_r * grip_r
    limit_f, limit_r = p.mu * grip_f * load_f, p.mu * grip_r * load_r
    top, reverse_below = p.top_speed_mps, p.reverse_below_mps
    horizontal = cos_slope  # travel along a slope covers less ground
    x, y, yaw = state.x_m, state.y_m, state.yaw_rad
    v_x, v_y, r = state.v_x_mps, state.v_y_mps, state.r_radps
    for _ in range(substeps):
        # Longitudinal: drive/brake, rolling resistance, aerodynamic drag, gravity along the
        # slope.
        f_x = longitudinal_force(v_x, controls, p)
        f_x -= _smooth_sign(v_x) * c_rr * normal_n
        f_x -= drag * v_x * abs(v_x)
        f_x -= gravity
        new_v_x = v_x + f_x / mass * dt_s
        if brake > 0.0 or (throttle < 0.0 and v_x > reverse_below):
            # Brakes stop the car; they never push it backwards through zero.
            if v_x > 0.0 > new_v_x or v_x < 0.0 < new_v_x:
                new_v_x = 0.0
        if new_v_x > top and f_x > 0.0:
            new_v_x = max(v_x, top)

        # Lateral: dynamic single-track model with linear tyres, saturated at mu * load.
        speed = abs(v_x)
        weight = min(max((speed - blend_low) / blend_span, 0.0), 1.0)
        if weight > 0.0:
            sign = math.copysign(1.0, v_x)
            alpha_f = delta - math.atan2(v_y + l_f * r, speed) * sign
            alpha_r = -math.atan2(v_y - l_r * r, speed) * sign
            f_yf = _saturate(stiffness_f * alpha_f, limit_f)
            f_yr = _saturate(stiffness_r * alpha_r, limit_r)
            dyn_v_y = v_y + ((f_yf * cos_delta + f_yr) / mass - v_x * r) * dt_s
            dyn_r = r + (l_f * f_yf * cos_delta - l_r * f_yr) / yaw_inertia * dt_s
        else:
            dyn_v_y, dyn_r = 0.0, 0.0
        # Kinematic model (no slip): yaw rate from the wheel angle, lateral speed at the CG.
        kin_r = new_v_x * tan_delta / wheelbase
        kin_v_y = kin_r * l_r
        v_y = weight * dyn_v_y + (1.0 - weight) * kin_v_y
        r = weight * dyn_r + (1.0 - weight) * kin_r
        v_x = new_v_x

        # Pose from the new velocities (semi-implicit Euler).
        yaw = yaw + r * dt_s
        cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
        x = x + (v_x * cos_yaw - v_y * sin_yaw) * horizontal * dt_s
        y = y + (v_x * sin_yaw + v_y * cos_yaw) * horizontal * dt_s
        yaw = math.remainder(yaw, 2.0 * math.pi)
    return VehicleState(x_m=x, y_m=y, yaw_rad=yaw, v_x_mps=v_x, v_y_mps=v_y, r_radps=r,
                        wheel_angle_rad=delta)


def _saturate(force: float, limit: float) -> float:
    return min(max(force, -limit), limit)


def hold_on_slope_throttle(grade: float, params: VehicleParams) -> float:
    """Throttle that holds the car at rest on ``grade`` (closed form, for tests and launch)."""
    sin_slope = grade / math.sqrt(1.0 + grade * grade)
    return params.m * GRAVITY_MPS2 * sin_slope / params.max_drive_force_n
