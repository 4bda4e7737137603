"""The drive server's bookkeeping: the counters of its life and the state of each connection.

:class:`DriveStats` is what :meth:`~clonedrive.udacity.server.DriveServer.stats` returns and the
status line reports; :class:`Connection` is one connected simulator: its own policy (the
server's, forked, so two simulators drive as each would alone) and its own counters. Both are
plain records the server updates from its event loop; keeping them apart from the message
handling lets a reader see at once what is counted, and a test read the counts by name.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from clonedrive.drivers.policy import Policy

#: A repeated warning (a bad message, a refused upgrade, a NaN prediction) is logged in full the
#: first LOG_FIRST times for each reason, then once in LOG_EVERY, so a broken client cannot
#: flood the log.
LOG_FIRST = 20
LOG_EVERY = 100


def worth_logging(count: int) -> bool:
    """Whether the ``count``-th occurrence of a repeated warning is logged (see LOG_FIRST)."""
    return count <= LOG_FIRST or count % LOG_EVERY == 0


@dataclass
class DriveStats:
    """Counters of one server's life (read them with :meth:`DriveServer.stats`)."""

    connections: int = 0  # connections accepted, ever
    active_connections: int = 0
    messages: int = 0  # WebSocket messages received
    steer: int = 0  # telemetry answered with the policy's controls
    manual: int = 0  # telemetry null answered with manual
    safe: int = 0  # telemetry-like frames answered with the safe command
    pings: int = 0
    ignored: int = 0  # frames logged and not answered
    refused: dict[str, int] = field(default_factory=dict)  # upgrade refused: reason -> count
    idle_closed: int = 0  # connections closed for sending no telemetry
    frames_saved: int = 0
    frames_not_saved: int = 0  # image folder over its cap
    bad: dict[str, int] = field(default_factory=dict)  # reason -> count
    last_steering: float = 0.0
    last_throttle: float = 0.0
    last_speed_mph: float = 0.0
    nan_predictions: int = 0  # frames the policy counted as NaN/infinite predictions

    @property
    def bad_total(self) -> int:
        return sum(self.bad.values())


@dataclass
class Connection:
    """One connected simulator: its own policy (the server's, forked: its own speed controller,
    steering filter and hold) and its own counters."""

    sid: str
    policy: Policy
    telemetry: int = 0  #: telemetry events answered with steer or manual
    steer: int = 0  #: telemetry answered with the policy's controls
    safe: int = 0  #: telemetry-like frames answered with the safe command
    nan_predictions: int = 0  #: the policy's NaN count already added to the server's total


def policy_for_connection(policy: Policy) -> Policy:
    """The policy one connection drives with: its own fork where the policy keeps state per
    car (:meth:`~clonedrive.drivers.policy.NetworkPolicy.fork`), else the shared one."""
    fork = getattr(policy, "fork", None)
    return fork() if callable(fork) else policy


def nan_count(policy: Policy) -> int:
    """The NaN predictions ``policy`` has counted over its life (0 if it counts none)."""
    return int(getattr(policy, "nan_predictions", 0) or 0)
