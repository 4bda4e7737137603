"""Which WebSocket upgrades the drive server accepts: the checks made before a client is served.

A drive server steers a car, so a web page must not be able to drive it, and idle or extra
clients must not lock the simulator out. Each upgrade request is checked, in this order:

* two ``Origin`` or two ``Host`` headers get 400;
* an upgrade that carries an ``Origin`` header (every browser sends one; the simulator sends
  none) is refused with 403 unless it is the server's own origin (``http://127.0.0.1:PORT``,
  what websocket-client and python-socketio's client send; no page can come from there) or is
  listed in ``allowed_origins``;
* the ``Host`` header must name the bound address (loopback names for 127.0.0.1; any IP
  address when bound to all interfaces) or a name in ``allowed_hosts``, so a DNS-rebinding
  page cannot reach the server under its own domain name (403 otherwise);
* the path must be the Socket.IO path (404), the Engine.IO version 3 or 4 and the transport
  ``websocket`` (400);
* at most ``max_connections`` clients are served at once (503; idle ones are closed after
  ``idle_timeout_s``, so they cannot hold the slots).

:func:`refusal` is a pure function of the request and the server's state, so the rules are read
and tested in one place; the server counts and logs the refusals that carry a reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from websockets.http11 import Request

from clonedrive.udacity.server_config import DriveServerConfig

SOCKET_PATH = "/socket.io"


@dataclass(frozen=True)
class Refusal:
    """An upgrade the server answers with an HTTP error instead of a WebSocket."""

    status: int  #: the HTTP status
    detail: str  #: the response body (one line, without its line break)
    reason: str | None = None  #: the counted reason (``DriveStats.refused``); None: not counted


def refusal(request: Request, config: DriveServerConfig, port: int,
            active_connections: int) -> Refusal | None:
    """Why ``request`` is refused by a server with ``config`` bound to ``port`` and serving
    ``active_connections`` clients; None when it is accepted."""
    return (_header_refusal(request, config, port) or _path_refusal(request.path)
            or _busy_refusal(config, active_connections))


def _header_refusal(request: Request, config: DriveServerConfig, port: int) -> Refusal | None:
    origins, hosts = (request.headers.get_all(name) for name in ("Origin", "Host"))
    if len(origins) > 1 or len(hosts) > 1:
        return Refusal(400, "more than one Origin or Host header", "headers")
    origin, host = (values[0] if values else None for values in (origins, hosts))
    if origin is not None and not config.origin_allowed(origin, port):
        return Refusal(403, f"browser origin {origin!r} refused: the simulator sends no "
                       "Origin; allow one with --allow-origin", "origin")
    if not config.host_allowed(host):
        return Refusal(403, f"Host {host!r} does not name this server; allow it with "
                       "--allow-host", "host")
    return None


def _path_refusal(path: str) -> Refusal | None:
    url = urlsplit(path)
    if url.path.rstrip("/") != SOCKET_PATH:
        return Refusal(404, f"not found: the drive protocol is at {SOCKET_PATH}/")
    query = parse_qs(url.query)
    eio = query.get("EIO", ["3"])[-1]
    if eio not in ("3", "4"):
        return Refusal(400, f"unsupported Engine.IO version EIO={eio}")
    if query.get("transport", ["websocket"])[-1] != "websocket":
        return Refusal(400, "only the websocket transport is supported")
    return None


def _busy_refusal(config: DriveServerConfig, active_connections: int) -> Refusal | None:
    if active_connections >= config.max_connections:
        return Refusal(503, f"too many connections ({config.max_connections}; idle ones close "
                       f"after {config.idle_timeout_s:g} s)", "busy")
    return None
