"""Pilots for the session's autonomous mode, in this process: the expert autopilot and a model.

Both follow :class:`~clonedrive.manual.pilot.Pilot`: ``controls(obs)`` for each step,
``manual()`` while a person takes over, ``close()`` when autonomous mode ends.
"""

from __future__ import annotations

from clonedrive.drivers.policy import Policy
from clonedrive.sim.simulator import SimObservation
from clonedrive.world.track import Track
from clonedrive.world.vehicle import Controls


class ExpertPilot:
    """The expert (pure pursuit on the centre line, ``clonedrive record``'s driver)."""

    name = "expert"

    def __init__(self, track: Track, *, reverse: bool = False) -> None:
        from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy

        self.policy = ExpertPolicy(track, ExpertConfig(reverse=reverse))

    def controls(self, obs: SimObservation) -> Controls:
        return self.policy.act(obs).controls_applied

    def manual(self) -> None:
        """The expert steers from the state it sees: nothing to hold."""

    def close(self) -> None:
        """Nothing to release."""


class ModelPilot:
    """A steering model from the center camera (any model ``clonedrive drive`` serves), with
    its PI speed controller. The policy is loaded once and shared by every model mode."""

    def __init__(self, policy: Policy, name: str = "model") -> None:
        self.policy = policy
        self.name = name
        policy.reset()

    def controls(self, obs: SimObservation) -> Controls:
        steering, throttle = self.policy.act(obs.images["center"], obs.speed_mph)
        return Controls(steering=float(steering), throttle=float(throttle)).clipped()

    def manual(self) -> None:
        """A person drives this step; the network starts afresh from what it sees next."""

    def close(self) -> None:
        """The policy stays loaded for the next model mode."""
