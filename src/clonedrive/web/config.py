"""How ``clonedrive web`` listens, what it shows and what it accepts: :class:`WebConfig`.

A module without heavy imports, so that ``clonedrive web --help`` takes its defaults from here.
"""

from __future__ import annotations

import math
import secrets
from dataclasses import dataclass, field

from clonedrive.udacity.server_config import DriveServerConfig

DEFAULT_HOST = "127.0.0.1"
#: donkeycar's browser controller listens here; its users will look for it there.
DEFAULT_PORT = 8887
#: Where the record toggle records unless told otherwise.
DEFAULT_OUT_DIR = "data/web"
#: What the live view shows: the center camera, or left | center | right side by side.
VIEWS = ("center", "three")
#: Modes the page offers: who drives.
MANUAL, EXPERT, MODEL, TAKEOVER = "manual", "expert", "model", "takeover"
MODES = (MANUAL, EXPERT, MODEL, TAKEOVER)


def new_token() -> str:
    """A random secret for the page's URL (like Jupyter's)."""
    return secrets.token_urlsafe(18)


@dataclass(frozen=True)
class WebConfig:
    """Where the page is served and how its stream looks. Every default is defined here."""

    host: str = DEFAULT_HOST  #: IP address to bind (0.0.0.0: every interface, with a warning)
    port: int = DEFAULT_PORT  #: TCP port, 0 = any free one
    token: str = field(default_factory=new_token)  #: the secret every request must carry
    view: str = "center"  #: the first view (the page can switch)
    jpeg_quality: int = 80  #: quality of the streamed frames, 1-100 (recordings keep theirs)
    max_clients: int = 4  #: browser connections served at once; more get 503
    max_message_bytes: int = 4096  #: a longer message from a page closes its connection (1009)
    max_pending_inputs: int = 256  #: input messages waiting for the next step; more are refused
    realtime: bool = True  #: pace steps to the control rate (off: as fast as the CPU allows)

    def __post_init__(self) -> None:
        DriveServerConfig(host=self.host, port=self.port)  # names a bad host or port
        if self.view not in VIEWS:
            raise ValueError(f"view {self.view!r} is not one of {', '.join(VIEWS)}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in [1, 100], got {self.jpeg_quality}")
        for name in ("max_clients", "max_message_bytes", "max_pending_inputs"):
            if not getattr(self, name) >= 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if len(self.token) < 8 or not self.token.replace("-", "").replace("_", "").isalnum():
            raise ValueError("token must be at least 8 URL-safe characters (letters, digits, "
                             "- and _)")

    @property
    def listen(self) -> DriveServerConfig:
        """The address checks the drive server makes, reused: bound address, Host names."""
        return DriveServerConfig(host=self.host, port=self.port)

    @property
    def loopback_only(self) -> bool:
        return self.listen.loopback_only

    def host_allowed(self, header: str | None) -> bool:
        """Whether a request's ``Host`` header names this server (a browser always sends one;
        a request without one is refused)."""
        return header is not None and self.listen.host_allowed(header)

    def url(self, port: int, host_name: str | None = None) -> str:
        """The page's URL with the token, as printed for the person to open."""
        name = host_name or self.host
        if name in ("0.0.0.0", "::"):
            name = "127.0.0.1"  # on this machine; others use one of its addresses
        if ":" in name:
            name = f"[{name}]"
        return f"http://{name}:{port}/?token={self.token}"


def finite(value: object) -> float | None:
    """``value`` as a finite float, else None."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    value = float(value)
    return value if math.isfinite(value) else None
