"""The expert policy: pure pursuit on a target line, a speed profile from the curvature ahead.

The expert knows the track (it is the autopilot that produces training data, not a learner). Each
control step it:

1. picks a point on the **target line** (centreline plus a lateral offset profile that depends on
   the style) a lookahead distance ahead, growing with speed, and steers toward it by **pure
   pursuit** (Coulter 1992) measured from the rear axle, with the car's understeer compensated;
2. smooths the command like a good human with a mouse or wheel: a first-order low-pass filter and
   a steering-rate limit, so there are no keyboard-style +/-1 spikes;
3. optionally adds slowly varying **noise** (an Ornstein-Uhlenbeck process, seeded) to the
   steering it *applies*, while the *label* it reports is its clean command for the state the car
   is in (DART, Laskey et al. 2017): the data then shows recoveries with correct labels;
4. holds a target speed with a PI controller plus a feed-forward of grade, rolling resistance and
   drag. The set speed is a maximum: a precomputed profile limits the speed to
   ``sqrt(a_lat_max / |curvature|)`` on the line it drives, and a backward pass over the lap
   makes it brake in time (``v^2 <= v_curve^2 + 2 a_brake d``) for every curve ahead.
   The same profile without the set speed's cap (only the car's top speed) is the expert's
   **speed label**, ``ExpertAction.label_speed_mph``: the speed it would aim for here at any
   set speed, which a network's speed head learns (the recorder stores it).

Styles (all in the driving direction, which ``reverse`` flips):

- ``center``: the centreline;
- ``left`` / ``right``: a line at ``offset_fraction`` of the usable half-width (half the road
  width minus half the car's width) toward that edge;
- ``weave``: a slow sinusoid between the two edges (recovery data), random phase from ``rng``;
- ``turns``: drives the centreline, and marks as recordable only the samples where the road's
  |curvature| exceeds ``turn_curvature_per_m``.

Units: metres, seconds, radians; steering in [-1, 1] with + = right (Udacity convention),
throttle and brake in [0, 1]. Offsets and CTE: + = right of centre in the driving direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from clonedrive.base.udacity_spec import CONTROL_HZ
from clonedrive.world.vehicle import (
    AIR_DENSITY_KGPM3,
    GRAVITY_MPS2,
    MPH_TO_MPS,
    TOP_SPEED_MPH,
    Controls,
    VehicleParams,
)

if TYPE_CHECKING:  # annotations only: the CLI reads STYLES without loading the simulator
    from clonedrive.sim.simulator import SimObservation
    from clonedrive.world.track import Track

STYLES = ("center", "left", "right", "weave", "turns")


@dataclass(frozen=True)
class ExpertConfig:
    """How the expert drives."""

    style: str = "center"  #: one of :data:`STYLES`
    speed_mph: float = TOP_SPEED_MPH  #: set speed [mph]: a maximum; curves ahead lower it
    reverse: bool = False  #: drive the track backwards (the simulator must be reset likewise)
    offset_fraction: float = 0.6  #: left/right: fraction of the usable half-width off centre
    car_half_width_m: float = 0.9  #: half the car's body width [m] (a sedan is ~1.8 m wide)
    weave_fraction: float = 0.7  #: weave: amplitude as a fraction of the usable half-width
    weave_wavelength_m: float = 160.0  #: weave: distance of one full left-right cycle [m]
    turn_curvature_per_m: float = 1.0 / 80.0  #: turns: record where |curvature| exceeds this
    noise: float = 0.0  #: std of the steering noise added to the applied steering, [-1, 1] units
    noise_time_constant_s: float = 0.6  #: correlation time of the noise [s]
    noise_edge_margin_m: float = 0.4  #: no outward noise once the car's side is this near an edge
    noise_fade_margin_m: float = 1.0  #: outward noise fades out over this distance [m]
    noise_preview_s: float = 0.8  #: the noise gate looks at where the car drifts in this time
    lateral_accel_mps2: float = 0.5 * GRAVITY_MPS2  #: speed limit in curves: v^2 |k| <= this
    brake_decel_mps2: float = 3.0  #: deceleration planned before curves [m/s^2]
    lookahead_min_m: float = 4.0  #: pure pursuit lookahead at standstill [m]
    lookahead_time_s: float = 0.45  #: lookahead grows by this many seconds of travel
    steering_time_constant_s: float = 0.1  #: low-pass filter on the steering command [s]
    steering_rate_per_s: float = 2.5  #: steering can change at most this much per second
    speed_kp_per_s: float = 1.0  #: desired acceleration per m/s of speed error [1/s]
    speed_ki_per_s2: float = 0.3  #: integral gain [1/s^2]
    control_hz: float = CONTROL_HZ  #: rate at which act() is called [Hz]

    def __post_init__(self) -> None:
        if self.style not in STYLES:
            raise ValueError(f"style {self.style!r} is not one of {', '.join(STYLES)}")
        if not 0.0 < self.speed_mph <= 60.0:
            raise ValueError(f"speed_mph must be in (0, 60], got {self.speed_mph}")
        for name in ("offset_fraction", "weave_fraction"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {value}")
        if not 0.0 <= self.noise <= 1.0:
            raise ValueError(f"noise must be in [0, 1] (steering units), got {self.noise}")
        positive = ("car_half_width_m", "weave_wavelength_m", "noise_time_constant_s",
                    "noise_fade_margin_m",
                    "lateral_accel_mps2", "brake_decel_mps2", "lookahead_min_m",
                    "steering_rate_per_s", "control_hz")
        for name in positive:
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")


@dataclass(frozen=True)
class ExpertAction:
    """What the expert does this step."""

    controls_applied: Controls  #: what goes to the simulator (steering includes the noise)
    label_steering: float  #: the expert's clean steering for this state: the training label
    noise: float  #: steering noise added this step (applied - label before clipping)
    target_speed_mph: float  #: speed the expert aims for now
    label_speed_mph: float  #: the target with no set-speed cap (top speed only): the label
    target_offset_m: float  #: lateral offset of the target line here (+ = right)
    record: bool  #: False where the style does not want the sample (``turns`` on straights)


class ExpertPolicy:
    """An autopilot that drives ``track`` in a style; call :meth:`reset` with the simulator's."""

    def __init__(self, track: Track, config: ExpertConfig | None = None,
                 rng: np.random.Generator | None = None,
                 vehicle: VehicleParams | None = None) -> None:
        self.track = track
        self.config = config or ExpertConfig()
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.vehicle = vehicle or VehicleParams()
        self._dt_s = 1.0 / self.config.control_hz
        self._direction = -1.0 if self.config.reverse else 1.0
        p = self.vehicle
        #: understeer gradient [rad per m/s^2 of lateral acceleration] of the single-track model
        self._understeer = p.m / p.wheelbase_m * (p.l_r / p.C_f - p.l_f / p.C_r)
        self.reset()

    # ------------------------------------------------------------------ episode
    def reset(self) -> None:
        """Forget the filter, integrator and noise state; draw a new weave phase."""
        self._steering = 0.0
        self._speed_integral = 0.0
        self._noise = 0.0
        self._weave_phase = float(self.rng.uniform(0.0, 2.0 * math.pi))
        self._build_profiles()

    def _build_profiles(self) -> None:
        """Offset, |curvature| and speed limit on the track's 0.5 m grid, in driving order."""
        track, cfg = self.track, self.config
        n = len(track.s)
        self._ds_m = track.length_m / n
        s_dir = np.arange(n) * self._ds_m
        track_s = track.wrap(self._direction * s_dir)
        curvature = self._direction * track.curvature(track_s)
        # The largest |curvature| within +-3 m: the tightest part of the line near each point.
        half = max(1, int(round(3.0 / self._ds_m)))
        abs_k = np.abs(curvature)
        wide = np.max([np.roll(abs_k, shift) for shift in range(-half, half + 1)], axis=0)
        self._abs_curvature = wide
        self._offsets = self.offset_m(s_dir)
        # On an offset line the radius shrinks on the inside of a curve: k / (1 - k |o|).
        line_k = wide / np.maximum(1.0 - wide * np.abs(self._offsets), 0.2)
        line_k += np.abs(np.gradient(np.gradient(self._offsets, self._ds_m), self._ds_m))
        set_speed = cfg.speed_mph * MPH_TO_MPS
        curve_limit = np.sqrt(cfg.lateral_accel_mps2 / np.maximum(line_k, 1e-6))
        limit = np.minimum(curve_limit, set_speed)
        self._speed_profile = _brake_in_time(limit, self._ds_m, cfg.brake_decel_mps2)
        uncapped = np.minimum(curve_limit, self.vehicle.top_speed_mps)
        self._label_speed_profile = _brake_in_time(uncapped, self._ds_m, cfg.brake_decel_mps2)

    # ------------------------------------------------------------------ the target line
    def offset_m(self, s_m: np.ndarray | float) -> np.ndarray:
        """Lateral offset [m, + = right in the driving direction] of the target line at arc
        length ``s_m`` measured in the driving direction."""
        cfg = self.config
        s_m = np.asarray(s_m, dtype=float)
        if cfg.style in ("center", "turns"):
            return np.zeros_like(s_m)
        usable = np.maximum(0.5 * self.track.width_at(self._track_s(s_m)) - cfg.car_half_width_m,
                            0.0)
        if cfg.style == "weave":
            phase = 2.0 * math.pi * s_m / cfg.weave_wavelength_m + self._weave_phase
            return cfg.weave_fraction * usable * np.sin(phase)
        side = -1.0 if cfg.style == "left" else 1.0
        return side * cfg.offset_fraction * usable

    def _track_s(self, s_m: np.ndarray | float) -> np.ndarray:
        return self.track.wrap(self._direction * np.asarray(s_m, dtype=float))

    def _on_grid(self, table: np.ndarray, s_m: float) -> float:
        f = (s_m % self.track.length_m) / self._ds_m
        i0 = int(f) % len(table)
        t = f - int(f)
        return float(table[i0] * (1.0 - t) + table[(i0 + 1) % len(table)] * t)

    def speed_limit_mph(self, s_m: float) -> float:
        """The speed profile [mph] at arc length ``s_m`` (driving direction)."""
        return self._on_grid(self._speed_profile, s_m) / MPH_TO_MPS

    # ------------------------------------------------------------------ control
    def act(self, obs: SimObservation) -> ExpertAction:
        """The controls for one step from the simulator's observation."""
        cfg = self.config
        speed = obs.speed_mph * MPH_TO_MPS
        command = self._pursuit_steering(obs, speed)

        # A human's hand: low-pass filtered, rate limited.
        alpha = self._dt_s / (cfg.steering_time_constant_s + self._dt_s)
        wanted = self._steering + alpha * (command - self._steering)
        max_step = cfg.steering_rate_per_s * self._dt_s
        self._steering += min(max(wanted - self._steering, -max_step), max_step)
        label = self._steering

        noise = 0.0
        if cfg.noise > 0.0:
            decay = self._dt_s / cfg.noise_time_constant_s
            self._noise += -self._noise * decay + cfg.noise * math.sqrt(2.0 * decay) * float(
                self.rng.standard_normal())
            noise = self._noise * self._noise_gate(obs, self._noise)
        applied = min(max(label + noise, -1.0), 1.0)

        ahead_m = obs.s_m + 0.5 * speed
        target_speed = self._on_grid(self._speed_profile, ahead_m)
        throttle, brake = self._speed_control(obs, speed, target_speed)
        return ExpertAction(
            controls_applied=Controls(steering=applied, throttle=throttle, brake=brake),
            label_steering=label,
            noise=noise,
            target_speed_mph=target_speed / MPH_TO_MPS,
            label_speed_mph=self._on_grid(self._label_speed_profile, ahead_m) / MPH_TO_MPS,
            target_offset_m=self._on_grid(self._offsets, obs.s_m),
            record=self.wants_sample(obs.s_m),
        )

    def _noise_gate(self, obs: SimObservation, noise: float) -> float:
        """1, or less when the noise pushes the car toward an edge that it is near or heading
        for: judged at the worse of its lateral position now and in ``noise_preview_s`` (from
        its heading error), the gate falls linearly to 0 over the last ``noise_fade_margin_m``
        before the car's side comes within ``noise_edge_margin_m`` of the edge, so the expert
        can always recover from a perturbation."""
        cfg = self.config
        drift = -obs.speed_mph * MPH_TO_MPS * math.sin(obs.heading_error_rad)  # + = rightward
        ahead = obs.cte_m + drift * cfg.noise_preview_s
        side = math.copysign(1.0, noise)  # the edge the noise pushes toward: + = right
        outward = max(side * obs.cte_m, side * ahead)
        if outward <= 0.0:
            return 1.0
        half_width = 0.5 * float(self.track.width_at(float(self._track_s(obs.s_m))))
        margin = half_width - outward - cfg.car_half_width_m - cfg.noise_edge_margin_m
        return min(max(margin / cfg.noise_fade_margin_m, 0.0), 1.0)

    def wants_sample(self, s_m: float) -> bool:
        """Whether the style records the sample at ``s_m`` (``turns``: only in curves)."""
        if self.config.style != "turns":
            return True
        return self._on_grid(self._abs_curvature, s_m) > self.config.turn_curvature_per_m

    def _pursuit_steering(self, obs: SimObservation, speed_mps: float) -> float:
        """Pure pursuit from the rear axle to the target line, as steering in [-1, 1]."""
        cfg, p = self.config, self.vehicle
        cos_yaw, sin_yaw = math.cos(obs.yaw_rad), math.sin(obs.yaw_rad)
        rear_x = obs.x_m - p.l_r * cos_yaw
        rear_y = obs.y_m - p.l_r * sin_yaw
        lookahead = cfg.lookahead_min_m + cfg.lookahead_time_s * abs(speed_mps)
        s_target = obs.s_m + lookahead + p.l_f  # ahead of the front axle, not the CG
        offset = self._on_grid(self._offsets, s_target)
        x, y, _ = self.track.offset_point(float(self._track_s(s_target)),
                                          self._direction * offset)
        dx, dy = float(x) - rear_x, float(y) - rear_y
        forward = cos_yaw * dx + sin_yaw * dy
        left = -sin_yaw * dx + cos_yaw * dy
        distance_sq = max(forward * forward + left * left, 1e-6)
        curvature = 2.0 * left / distance_sq  # of the arc from the rear axle to the target
        wheel_angle = math.atan(p.wheelbase_m * curvature)
        wheel_angle += self._understeer * speed_mps * speed_mps * curvature
        return min(max(-wheel_angle / p.max_wheel_angle_rad, -1.0), 1.0)

    def _speed_control(self, obs: SimObservation, speed_mps: float,
                       target_mps: float) -> tuple[float, float]:
        """(throttle, brake) in [0, 1] from a PI law on speed plus a resistance feed-forward."""
        cfg, p = self.config, self.vehicle
        error = target_mps - speed_mps
        grade = math.tan(obs.pitch_rad)
        normal = p.m * GRAVITY_MPS2 / math.sqrt(1.0 + grade * grade)
        resist = normal * grade + p.c_rr * normal
        resist += 0.5 * AIR_DENSITY_KGPM3 * p.c_d_a_m2 * speed_mps * abs(speed_mps)
        accel = cfg.speed_kp_per_s * error + cfg.speed_ki_per_s2 * self._speed_integral
        force = p.m * accel + resist
        saturated = (force > p.max_drive_force_n and error > 0) or (
            force < -p.max_brake_force_n and error < 0)
        if not saturated:  # anti-windup: integrate only while the output can follow
            self._speed_integral = min(max(self._speed_integral + error * self._dt_s, -5.0), 5.0)
        if force >= 0.0:
            return min(force / p.max_drive_force_n, 1.0), 0.0
        return 0.0, min(-force / p.max_brake_force_n, 1.0)


def _brake_in_time(limit_mps: np.ndarray, ds_m: float, decel_mps2: float) -> np.ndarray:
    """Lower a closed loop's speed limit so that every point can be reached from the one before
    it by braking at ``decel_mps2``: v[i]^2 <= v[i+1]^2 + 2 a ds, around the loop twice."""
    speed_sq = np.square(limit_mps).tolist()
    n = len(speed_sq)
    step = 2.0 * decel_mps2 * ds_m
    for k in range(2 * n - 1, -1, -1):
        i, ahead = k % n, (k + 1) % n
        reachable = speed_sq[ahead] + step
        if reachable < speed_sq[i]:
            speed_sq[i] = reachable
    return np.sqrt(np.asarray(speed_sq))
