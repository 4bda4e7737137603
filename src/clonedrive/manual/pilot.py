"""Who drives a manual session's car in autonomous mode: the :class:`Pilot` interface, and a
drive server as the default pilot.

Autonomous mode is the Udacity simulator's: a drive server steers, through
:class:`~clonedrive.udacity.client.SimulatorClient`, and is sent the manual-mode telemetry while a
person takes over. Anything else that decides from the observation -- the expert, a model in
this process (``clonedrive web``) -- can be a pilot too; the session does not know which.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from clonedrive.manual.config import ManualConfig
from clonedrive.world.vehicle import Controls

if TYPE_CHECKING:  # the simulator loads when a track opens, not when the CLI reads defaults
    from clonedrive.sim.simulator import SimObservation


class Pilot(Protocol):
    """Who drives in autonomous mode: a drive server (the default) or anything that decides from
    the observation."""

    name: str  #: shown on the HUD

    def controls(self, obs: SimObservation) -> Controls | None:
        """This step's controls; None: the car rolls on as it is."""
        ...

    def manual(self) -> None:
        """A person has the car this step."""
        ...

    def close(self) -> None: ...


class ServerPilot:
    """A drive server as the pilot, through the Udacity simulator's side of the protocol."""

    def __init__(self, client) -> None:
        self.client = client
        self.name = client.url

    def controls(self, obs: SimObservation) -> Controls | None:
        return self.client.controls_for(obs.images["center"], obs.steering, obs.throttle,
                                        obs.speed_mph)

    def manual(self) -> None:
        self.client.manual()

    def close(self) -> None:
        self.client.close()


def connect_server(config: ManualConfig) -> ServerPilot:
    """The drive server ``config`` names, connected, as a pilot. Raises
    :class:`~clonedrive.udacity.client.DriveServerError` when it cannot connect."""
    from clonedrive.udacity.client import ClientConfig, SimulatorClient

    client = SimulatorClient(ClientConfig(
        host=config.server_host, port=config.server_port,
        connect_timeout_s=config.connect_timeout_s, reply_timeout_s=config.reply_timeout_s))
    client.connect()
    return ServerPilot(client)
