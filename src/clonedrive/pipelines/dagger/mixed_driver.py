"""Who drives each step of a DAgger collection: the network, the expert, or a safety
takeover."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


class MixedDriver:
    """A runner :class:`~clonedrive.episode.runner.Driver`: per car and step, the expert's
    controls with probability ``beta`` (or during a safety takeover), else the network's.

    The network's decisions come from one prediction call for all cars
    (:class:`~clonedrive.episode.drivers.PolicyDriver`); each car has its own expert at the
    wheel, called every step so that its steering filter follows the car whoever drives.
    ``Decision.detail`` says who drove: ``"network"``, ``"expert"`` or ``"takeover"``.
    """

    def __init__(self, policy, experts: Sequence, set_speeds_mph: Sequence[float], *,
                 beta: float, rng: np.random.Generator, margin_m: float = 0.3,
                 preview_s: float = 1.0, release_cte_m: float = 0.5, min_takeover_s: float = 1.0,
                 control_hz: float = 15.0) -> None:
        from clonedrive.episode.drivers import PolicyDriver

        self.network = PolicyDriver(policy, set_speeds_mph)
        self.experts = list(experts)
        self.beta = float(beta)
        self.rng = rng
        self.margin_m = float(margin_m)
        self.preview_s = float(preview_s)
        self.release_cte_m = float(release_cte_m)
        self.min_takeover_steps = int(math.ceil(min_takeover_s * control_hz))
        count = len(self.experts)
        self.takeovers = [0] * count
        self.steps_by = [{"network": 0, "expert": 0, "takeover": 0} for _ in range(count)]
        self._taken = [0] * count  # steps since the takeover began, 0 = none

    def reset(self, car: int) -> None:
        self.network.reset(car)
        self.experts[car].reset()
        self._taken[car] = 0

    def intervened(self, car: int, obs) -> None:
        self.network.intervened(car, obs)
        self._taken[car] = 0

    def about_to_leave(self, car: int, obs) -> bool:
        """The car's outer front tyre is, now or ``preview_s`` ahead on its heading, within
        ``margin_m`` of the road's edge."""
        from clonedrive.world.vehicle import MPH_TO_MPS

        expert = self.experts[car]
        heading = obs.heading_error_rad
        drift = -obs.speed_mph * MPH_TO_MPS * math.sin(heading)  # lateral speed, + = rightward
        ahead = obs.cte_m + drift * self.preview_s
        # The front tyre sits half the car's width to the side, and the axle ahead of the
        # centre reaches further out when the car is yawed.
        corner = expert.config.car_half_width_m * abs(math.cos(heading)) \
            + expert.vehicle.l_f * abs(math.sin(heading))
        half_width = 0.5 * float(expert.track.width_at(float(expert.track.wrap(obs.s_m))))
        outward = max(abs(obs.cte_m), abs(ahead))
        return outward + corner + self.margin_m > half_width

    def act(self, cars: Sequence[int], observations: Sequence) -> list:
        from clonedrive.episode.runner import Decision

        network = self.network.act(cars, observations)
        decisions = []
        for car, obs, mine in zip(cars, observations, network, strict=True):
            expert = self.experts[car].act(obs)
            who = "network"
            if self._taken[car] > 0:
                self._taken[car] += 1
                back = (abs(obs.cte_m) < self.release_cte_m
                        and abs(obs.heading_error_rad) < math.radians(5.0))
                if back and self._taken[car] > self.min_takeover_steps:
                    self._taken[car] = 0
                else:
                    who = "takeover"
            if who == "network" and self.about_to_leave(car, obs):
                self._taken[car] = 1
                self.takeovers[car] += 1
                who = "takeover"
            if who == "network" and self.rng.random() < self.beta:
                who = "expert"
            self.steps_by[car][who] += 1
            controls = mine.controls if who == "network" else expert.controls_applied
            decisions.append(Decision(controls=controls, detail=who))
        return decisions
