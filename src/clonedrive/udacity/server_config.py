"""How the drive server listens and what it accepts: :class:`DriveServerConfig`.

A module of its own, without the server's imports, so that ``clonedrive drive --help`` can take
its defaults from here cheaply.
"""

from __future__ import annotations

import ipaddress
import math
from dataclasses import dataclass
from urllib.parse import urlsplit

from clonedrive.base.udacity_spec import PORT

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = PORT
#: A text frame longer than this (characters = bytes: frames are ASCII) gets the safe reply.
MAX_MESSAGE_BYTES = 1 << 20

#: Host header names that always mean this machine.
_LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
#: Close code for a connection closed for sending no telemetry (4000-4999: application codes).
IDLE_CLOSE_CODE = 4000


@dataclass(frozen=True)
class DriveServerConfig:
    """How the drive server listens and what it accepts. Defaults are those of ``clonedrive
    drive``; every one is checked here."""

    host: str = DEFAULT_HOST  #: IP address to bind (0.0.0.0 or :: for every interface)
    port: int = DEFAULT_PORT  #: TCP port, 0 = any free one
    image_folder: str | None = None  #: save each received frame here (None: don't save)
    status_interval_s: float = 5.0  #: seconds between status log lines, 0 = none
    max_message_bytes: int = MAX_MESSAGE_BYTES  #: a longer frame gets the safe reply
    max_connections: int = 4  #: clients served at once; more get 503
    idle_timeout_s: float = 30.0  #: close a connection that sends no telemetry this long [s]
    allowed_origins: tuple[str, ...] = ()  #: browser Origin values accepted (none by default)
    allowed_hosts: tuple[str, ...] = ()  #: Host header names accepted besides the bound address
    image_folder_max_mb: float = 2048.0  #: stop saving frames once the folder holds this [MB]

    def __post_init__(self) -> None:
        if self.host != "localhost":
            try:
                ipaddress.ip_address(self.host)
            except ValueError:
                raise ValueError(
                    f"host {self.host!r} is not an IP address; bind 127.0.0.1 (this machine "
                    "only), 0.0.0.0 (every interface) or one of this machine's addresses"
                ) from None
        if isinstance(self.port, bool) or not isinstance(self.port, int) \
                or not 0 <= self.port <= 65535:
            raise ValueError(f"port {self.port!r} is not a TCP port (0-65535)")
        if not (math.isfinite(self.status_interval_s) and self.status_interval_s >= 0):
            raise ValueError(f"status interval must be >= 0 s, got {self.status_interval_s}")
        if self.max_message_bytes < 1024:
            raise ValueError(f"max_message_bytes must be at least 1024, got "
                             f"{self.max_message_bytes}")
        if self.max_connections < 1:
            raise ValueError(f"max connections must be at least 1, got {self.max_connections}")
        if not (math.isfinite(self.idle_timeout_s) and self.idle_timeout_s > 0):
            raise ValueError(f"idle timeout must be a positive number of seconds, got "
                             f"{self.idle_timeout_s}")
        if not (math.isfinite(self.image_folder_max_mb) and self.image_folder_max_mb > 0):
            raise ValueError(f"image folder cap must be a positive number of MB, got "
                             f"{self.image_folder_max_mb}")
        for origin in self.allowed_origins:
            if not origin or any(char.isspace() for char in origin):
                raise ValueError(f"allowed origin {origin!r} must be one word, like "
                                 "http://localhost:8000")
        object.__setattr__(self, "allowed_origins", tuple(self.allowed_origins))
        object.__setattr__(self, "allowed_hosts",
                           tuple(_host_name(host) for host in self.allowed_hosts))

    @property
    def loopback_only(self) -> bool:
        """True when only this machine can connect."""
        return self.host == "localhost" or ipaddress.ip_address(self.host).is_loopback

    def origin_allowed(self, origin: str, port: int) -> bool:
        """Whether an upgrade's ``Origin`` header is accepted: listed in ``allowed_origins``, or
        this server's own origin, ``http(s)://NAME:PORT`` with the bound ``port`` and a NAME
        that :meth:`host_allowed` accepts (what websocket-client sends by default; no web page
        has it, since this server serves none)."""
        if origin in self.allowed_origins:
            return True
        try:
            url = urlsplit(origin)
            origin_port = url.port
        except ValueError:
            return False
        if url.scheme not in ("http", "https") or url.hostname is None or origin_port != port:
            return False
        if url.path or url.query or url.fragment or url.username is not None:
            return False
        return self.host_allowed(url.netloc)

    def host_allowed(self, header: str | None) -> bool:
        """Whether a request's ``Host`` header names this server (None: no header, allowed:
        browsers always send one)."""
        if header is None:
            return True
        name = _host_name(header)
        if name in _LOOPBACK_NAMES or name in self.allowed_hosts or name == _host_name(self.host):
            return True
        wildcard = self.host != "localhost" and ipaddress.ip_address(self.host).is_unspecified
        if wildcard:  # served on every interface: any address of ours, never a domain name
            try:
                ipaddress.ip_address(name)
            except ValueError:
                return False
            return True
        return False


def _host_name(host: str) -> str:
    """The host part of a ``Host`` header or address: no port, no brackets, lower case."""
    text = host.strip().lower().rstrip(".")
    if text.startswith("["):  # [::1]:4567
        return text[1:].split("]", 1)[0]
    if text.count(":") == 1:  # name:port or a.b.c.d:port (an IPv6 address has several)
        return text.split(":", 1)[0]
    return text
