"""How the replayed car moves away from the path the human drove.

The replayed car and the recorded one drive at the same recorded speed; only their steering
differs. Its state relative to the recorded car is a lateral offset and a heading error (both
right = +), which say where the recorded view is synthesised from. Two vehicle models:

- ``kinematic`` (the default): a kinematic bicycle (no slip, the wheel angle turns the car at
  once): the heading error grows with the difference of the two curvatures, the offset with the
  heading error.
- ``dynamic``: both cars run through the simulator's own single-track model
  (:func:`clonedrive.world.vehicle.integrate`, tyre slip and yaw inertia, at the simulator's
  physics rate). Each frame both start where the last one left them, the recorded car at the
  origin facing +x; the replayed car's offset is its lateral distance from the recorded car
  across the recorded car's new heading, and the heading error the difference of their yaws.
  A steering command takes as long to turn the car as it does in closed loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from clonedrive.world.vehicle import (
    MPH_TO_MPS,
    PHYSICS_HZ,
    Controls,
    VehicleParams,
    VehicleState,
    integrate,
)

#: The vehicle models a replay can use.
VEHICLE_MODELS = ("kinematic", "dynamic")


def check_vehicle_model(name: str) -> None:
    """ValueError naming the choices when ``name`` is not one of :data:`VEHICLE_MODELS`."""
    if name not in VEHICLE_MODELS:
        raise ValueError(f"vehicle model must be one of {', '.join(VEHICLE_MODELS)}, "
                         f"got {name!r}")


@dataclass
class RelativeMotion:
    """The replayed car's offset and heading error from the recorded car, advanced frame by
    frame by the replayed and the recorded steering at the recorded speed."""

    model: str = "kinematic"
    params: VehicleParams = VehicleParams()
    offset_m: float = 0.0  #: right = +
    heading_rad: float = 0.0  #: right = +

    def __post_init__(self) -> None:
        check_vehicle_model(self.model)
        self._replayed = (0.0, 0.0)  # (lateral speed m/s, yaw rate rad/s), vehicle frame
        self._recorded = (0.0, 0.0)

    def put_back(self) -> None:
        """An intervention: the car is back on the recorded path, moving as the recorded one."""
        self.offset_m = self.heading_rad = 0.0
        self._replayed = self._recorded

    def advance(self, steering: float, recorded_steering: float, speed_mph: float,
                dt_s: float) -> float:
        """Move both cars ``dt_s`` seconds on; returns the distance travelled [m]."""
        speed = speed_mph * MPH_TO_MPS
        if self.model == "kinematic":
            self._kinematic(steering, recorded_steering, speed * dt_s)
        elif speed > 0.0 and dt_s > 0.0:
            self._dynamic(steering, recorded_steering, speed, dt_s)
        return speed * dt_s

    def _kinematic(self, steering: float, recorded_steering: float, step_m: float) -> None:
        max_wheel = self.params.max_wheel_angle_rad
        turn = step_m / self.params.wheelbase_m * (
            math.tan(steering * max_wheel) - math.tan(recorded_steering * max_wheel))
        self.offset_m += step_m * math.sin(self.heading_rad + 0.5 * turn)
        self.heading_rad += turn

    def _dynamic(self, steering: float, recorded_steering: float, speed: float,
                 dt_s: float) -> None:
        substeps = max(1, round(dt_s * PHYSICS_HZ))
        # Vehicle frame: y left, yaw counter-clockwise; the replay's offset and heading: right.
        replayed = self._step(VehicleState(y_m=-self.offset_m, yaw_rad=-self.heading_rad,
                                           v_x_mps=speed, v_y_mps=self._replayed[0],
                                           r_radps=self._replayed[1]),
                              steering, dt_s / substeps, substeps)
        recorded = self._step(VehicleState(v_x_mps=speed, v_y_mps=self._recorded[0],
                                           r_radps=self._recorded[1]),
                              recorded_steering, dt_s / substeps, substeps)
        across = (-(replayed.x_m - recorded.x_m) * math.sin(recorded.yaw_rad)
                  + (replayed.y_m - recorded.y_m) * math.cos(recorded.yaw_rad))
        self.offset_m = -across
        self.heading_rad = -math.remainder(replayed.yaw_rad - recorded.yaw_rad, 2.0 * math.pi)
        self._replayed = (replayed.v_y_mps, replayed.r_radps)
        self._recorded = (recorded.v_y_mps, recorded.r_radps)

    def _step(self, state: VehicleState, steering: float, dt_s: float,
              substeps: int) -> VehicleState:
        # No throttle: both cars coast through the frame (they lose the same few mm/s), and the
        # next frame starts them again at the recorded speed.
        return integrate(state, Controls(steering=steering), dt_s, self.params,
                         substeps=substeps)
