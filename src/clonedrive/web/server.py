"""The page's server: one HTTP page and one WebSocket on one port, guarded by a token.

``GET /?token=T`` serves the page; the page opens ``/ws?token=T``, sends its inputs as JSON
text (:mod:`clonedrive.web.messages`) and receives one binary message per frame: a 4-byte
big-endian length, that many bytes of JSON state, then the JPEG. A page that falls behind gets
the newest frame only (one waiting frame per page, so memory stays bounded).

Refused, before anything else is read:

* any request whose ``Host`` header does not name the bound address (loopback names for
  127.0.0.1, any IP address when bound to every interface): a DNS-rebinding page cannot reach
  the server under its own name (403);
* any request without the token, or with a wrong one (403; compared in constant time);
* a WebSocket whose ``Origin`` is not this page's own ``http://<Host>`` (403): another site's
  page cannot drive the car, even from the person's own browser;
* more than ``max_clients`` pages at once (503).

Garbage on the socket is answered with an error message naming what is wrong (binary data,
not JSON, unknown type or field, out-of-range values) and the connection is kept; a message
longer than ``max_message_bytes`` closes that connection (1009) and the server keeps serving.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
import threading
from importlib import resources
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from clonedrive.web.config import WebConfig
from clonedrive.web.controller import Controller, Frame
from clonedrive.web.messages import MessageError, parse

logger = logging.getLogger("clonedrive.web")

PAGE_PATH = "/"
SOCKET_PATH = "/ws"
_PAGE_HEADERS = (
    ("Content-Type", "text/html; charset=utf-8"),
    ("Cache-Control", "no-store"),
    ("Referrer-Policy", "no-referrer"),  # the token stays out of other sites' logs
    ("X-Frame-Options", "DENY"),
    ("Content-Security-Policy", "default-src 'none'; script-src 'unsafe-inline'; "
     "style-src 'unsafe-inline'; img-src blob: data:; connect-src 'self'; "
     "frame-ancestors 'none'"),
)


def _single(request: Request, name: str, default: str | None = None) -> str | None:
    """A header's one value; ``default`` when absent; None (refused) when sent twice."""
    values = request.headers.get_all(name)
    if not values:
        return default
    return values[0] if len(values) == 1 else None


def frame_message(frame: Frame) -> bytes:
    """A frame as the page receives it: length of the state, the state (JSON), the JPEG."""
    state = json.dumps(frame.state, separators=(",", ":")).encode()
    return len(state).to_bytes(4, "big") + state + frame.jpeg


class _Page:
    """One connected page: the newest frame not yet sent to it."""

    def __init__(self) -> None:
        self.frame: Frame | None = None
        self.ready = asyncio.Event()


class WebServer:
    """Serve the page for ``controller`` (which some other thread steps) from a background
    thread: :meth:`start` returns the bound port, :meth:`publish` hands it each new frame,
    :meth:`stop` ends it."""

    def __init__(self, controller: Controller, config: WebConfig) -> None:
        self.controller = controller
        self.config = config
        self.port = config.port
        self.refused: dict[str, int] = {}  #: refusals by reason (host, token, origin, busy)
        self.bad_messages = 0
        self._pages: set[_Page] = set()
        self._page_html = resources.files("clonedrive.web").joinpath("page.html").read_bytes()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    # ------------------------------------------------------------------ running
    def start(self, timeout_s: float = 10.0) -> int:
        """Listen from a daemon thread; returns the bound port (raises OSError if taken)."""
        self._thread = threading.Thread(target=self._thread_main, name="web-server",
                                        daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout_s):
            raise TimeoutError(f"web server did not start within {timeout_s} s")
        if self._error is not None:
            self._thread.join()
            raise self._error
        return self.port

    def stop(self, timeout_s: float = 10.0) -> None:
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(stop.set)
            except RuntimeError:  # the loop closed meanwhile
                pass
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None

    @property
    def url(self) -> str:
        return self.config.url(self.port)

    @property
    def watched(self) -> bool:
        """At least one page is connected."""
        return bool(self._pages)

    def publish(self, frame: Frame) -> None:
        """Send ``frame`` to every page (any thread); a page still busy skips to it."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(self._fan_out, frame)
            except RuntimeError:
                pass

    def _fan_out(self, frame: Frame) -> None:
        for page in self._pages:
            page.frame = frame
            page.ready.set()

    def _thread_main(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as error:
            if not self._ready.is_set():
                self._error = error
                self._ready.set()
            else:
                logger.exception("web server stopped with an error")

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        async with serve(self._handle, self.config.host, self.config.port,
                         process_request=self._check_request,
                         max_size=self.config.max_message_bytes, max_queue=8,
                         server_header=None) as server:
            self.port = server.sockets[0].getsockname()[1]
            self._ready.set()
            await self._stop.wait()

    # ------------------------------------------------------------------ requests
    def _check_request(self, connection: ServerConnection, request: Request) -> Response | None:
        host = _single(request, "Host")
        if not self.config.host_allowed(host):
            return self._refuse(connection, "host", f"Host {str(host)[:60]!r} does not name "
                                "this server: open the URL clonedrive web printed")
        url = urlsplit(request.path)
        if url.path not in (PAGE_PATH, SOCKET_PATH):
            return connection.respond(404, "not found\n")
        token = parse_qs(url.query).get("token", [""])[-1]
        if not hmac.compare_digest(token.encode(), self.config.token.encode()):
            return self._refuse(connection, "token", "this page needs its token: open the "
                                "URL clonedrive web printed (it ends in ?token=...)")
        if url.path == PAGE_PATH:
            return Response(200, "OK", Headers(_PAGE_HEADERS), self._page_html)
        origin = _single(request, "Origin", default="")
        if origin != "" and origin != f"http://{host}":
            return self._refuse(connection, "origin", f"a page from {str(origin)[:60]!r} may not "
                                "drive: only this server's own page may")
        if len(self._pages) >= self.config.max_clients:
            return self._refuse(connection, "busy", f"{self.config.max_clients} pages are "
                                "already connected", status=503)
        return None

    def _refuse(self, connection: ServerConnection, reason: str, detail: str, *,
                status: int = 403) -> Response:
        self.refused[reason] = self.refused.get(reason, 0) + 1
        if self.refused[reason] <= 20:
            logger.warning("refused a request from %s (%s): %s", connection.remote_address,
                           reason, detail)
        return connection.respond(status, f"clonedrive web: {detail}\n")

    async def _handle(self, websocket: ServerConnection) -> None:
        page = _Page()
        self._pages.add(page)
        sender = asyncio.create_task(self._send_frames(websocket, page))
        try:
            await websocket.send(json.dumps(self._hello()))
            async for message in websocket:
                error = self._on_message(message)
                if error is not None:
                    await websocket.send(json.dumps({"type": "error", "message": error}))
        except ConnectionClosed:
            pass
        finally:
            self._pages.discard(page)
            sender.cancel()
            if not self._pages:  # nobody left to hold a key: let everything go
                self.controller.submit_release()

    def _on_message(self, message: str | bytes) -> str | None:
        try:
            command = parse(message)
        except MessageError as error:
            self.bad_messages += 1
            return str(error)
        if not self.controller.submit(command):
            return "too many inputs waiting for the next step: this one was dropped"
        return None

    async def _send_frames(self, websocket: ServerConnection, page: _Page) -> None:
        try:
            while True:
                await page.ready.wait()
                page.ready.clear()
                await websocket.send(frame_message(page.frame))
        except ConnectionClosed:
            pass

    def _hello(self) -> dict:
        from clonedrive.sim.conditions import TRAINING_LOOKS
        from clonedrive.web.config import MODES, VIEWS

        controller = self.controller
        return {"type": "hello", "tracks": controller.track_choices,
                "looks": ["clear", *[look for look in TRAINING_LOOKS if look != "clear"]],
                "modes": list(MODES), "views": list(VIEWS),
                "model": controller.policy is not None, "model_name": controller.model_name}
