"""Drivers (the runner's adapters, one car or N) for the policies of :mod:`clonedrive.drivers`:
the expert (:class:`ExpertDriver`) and the network (:class:`PolicyDriver`).

(The other two kinds sit with what they talk to: the remote drive server is
:class:`clonedrive.udacity.client.ServerDriver`, a person is the manual window's session.)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from clonedrive.drivers.expert import ExpertPolicy
from clonedrive.drivers.policy import NetworkPolicy, SpeedController
from clonedrive.episode.runner import Decision
from clonedrive.sim.simulator import Controls, SimObservation


class ExpertDriver:
    """The expert driving one car: applies its (possibly noisy) controls and labels the step
    with its clean steering; ``record`` is False where its style does not want the sample."""

    def __init__(self, expert: ExpertPolicy) -> None:
        self.expert = expert

    def reset(self) -> None:
        self.expert.reset()

    def act(self, obs: SimObservation) -> Decision:
        action = self.expert.act(obs)
        return Decision(controls=action.controls_applied, steering_label=action.label_steering,
                        record=action.record, detail=action)

    def intervened(self, obs: SimObservation) -> None:
        """The expert steers from the state it sees: nothing to forget."""


class PolicyDriver:
    """A :class:`~clonedrive.drivers.policy.NetworkPolicy` driving N cars: one prediction
    call for all their center frames per step (each frame through the network alone, so a
    car's steering does not depend on the others'), and a PI speed controller per car holding
    that car's set speed (``set_speeds_mph[car]``; with a speed head the learned target speed
    capped by it, with the policy's ``slow_in_curves`` lower in bends).

    An intervention leaves the controller as it is, as it leaves a remote drive server's (which
    is never told): the car is put back at its set speed, where the integral term that held it
    there is still right. So ``evaluate`` and ``autonomous`` drive alike after one."""

    def __init__(self, policy: NetworkPolicy, set_speeds_mph: Sequence[float]) -> None:
        self.policy = policy
        self.set_speeds_mph = [float(speed) for speed in set_speeds_mph]
        self.controllers = [self._controller(speed) for speed in self.set_speeds_mph]
        #: Per car: the policy's steering filter (a pass-through unless steering_filter_s).
        self.filters = [policy.new_steering_filter() for _ in self.set_speeds_mph]
        #: Per car: frames whose steering prediction was NaN or infinite (driven straight).
        self.nan_predictions = [0] * len(self.set_speeds_mph)

    def _controller(self, set_speed_mph: float) -> SpeedController:
        gains = self.policy.controller
        return SpeedController(set_speed_mph, kp=gains.kp, ki=gains.ki)

    def reset(self, car: int) -> None:
        self.controllers[car] = self._controller(self.set_speeds_mph[car])
        self.filters[car].reset()

    def act(self, cars: Sequence[int], observations: Sequence[SimObservation]
            ) -> list[Decision]:
        frames = np.stack([obs.images["center"] for obs in observations])
        steering, learned = self.policy.predict(frames)
        for car, bad in zip(cars, self.policy.last_nonfinite, strict=True):
            self.nan_predictions[car] += int(bad)
        decisions = []
        for index, (car, obs, steer) in enumerate(zip(cars, observations, steering, strict=True)):
            steer = self.filters[car].update(float(steer), obs.speed_mph)
            controller = self.controllers[car]
            controller.set_speed_mph = self.policy.target_speed_mph(
                float(steer), set_speed_mph=self.set_speeds_mph[car],
                learned_speed_mph=None if learned is None else float(learned[index]),
                disagreement=float(self.policy.last_disagreement[index]))
            throttle = controller.update(obs.speed_mph)
            decisions.append(Decision(controls=Controls(steering=float(steer), throttle=throttle)))
        return decisions

    def intervened(self, car: int, obs: SimObservation) -> None:
        """Nothing to forget (see the class)."""
