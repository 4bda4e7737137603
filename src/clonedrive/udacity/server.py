"""The drive server: what Udacity's ``drive.py`` does, for the Udacity simulator and for ours.

The simulator connects to ``ws://127.0.0.1:4567/socket.io/?EIO=4&transport=websocket`` and sends
one ``telemetry`` event per command it receives (lock-step). For each one the server decodes the
center-camera JPEG (BGR -> RGB), asks the policy for ``(steering, throttle)`` and answers
``42["steer",{"steering_angle":"<str>","throttle":"<str>"}]``. The Engine.IO 3 / Socket.IO
framing is done here by hand over a plain WebSocket (see :mod:`clonedrive.udacity.protocol`), so
events are accepted whether or not the client ever sent a Socket.IO CONNECT (the simulator never
does -- the reason python-socketio 5 servers leave the car standing).

What each received message gets -- ``steer``, ``manual``, the safe command, a pong, or nothing
-- is :mod:`clonedrive.udacity.triage`.

Memory is bounded: a message over ``max_message_bytes`` (1 MiB; a real frame is ~15 KB) is
refused unread beyond its size, one over the WebSocket limit (2 MiB) makes ``websockets`` close
that connection (code 1009) while the server keeps serving, JPEG sizes are read from the header
before decoding, and at most ``max_connections`` clients are served at once.

Unlike drive.py the server binds 127.0.0.1 unless told otherwise, gives each connected simulator
its own policy state (speed controller, steering filter and hold, counters; see
:meth:`~clonedrive.drivers.policy.NetworkPolicy.fork`), so two simulators drive as each would
alone, and never deletes an existing image folder (frames are added to it).

It cannot be hijacked from a web page or starved by idle clients (:class:`DriveServerConfig`):
upgrades from browser origins, under foreign ``Host`` names or beyond ``max_connections`` are
refused (:mod:`clonedrive.udacity.admission`); a connection that sends no telemetry for
``idle_timeout_s``, or does not read its replies for that long, is closed (answering pings does
not count), so idle clients cannot hold the ``max_connections`` slots and lock the simulator out
with 503; saved frames stop once the image folder holds ``image_folder_max_mb``
(:mod:`clonedrive.udacity.frame_folder`), with one warning; driving goes on. The counters are
:mod:`clonedrive.udacity.drive_stats`.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextvars
import logging
import os
import threading
import time
import uuid
from dataclasses import replace
from pathlib import Path

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from clonedrive.drivers.policy import Policy
from clonedrive.udacity import protocol
from clonedrive.udacity.admission import SOCKET_PATH, refusal
from clonedrive.udacity.drive_stats import (
    Connection,
    DriveStats,
    nan_count,
    policy_for_connection,
    worth_logging,
)
from clonedrive.udacity.frame_folder import FrameFolder
from clonedrive.udacity.server_config import IDLE_CLOSE_CODE, DriveServerConfig
from clonedrive.udacity.triage import (
    CLOSE,
    DISCONNECT,
    IGNORE,
    MANUAL,
    PING,
    SAFE,
    TELEMETRY,
    triage,
)

logger = logging.getLogger("clonedrive.udacity")

#: ``websockets`` closes a connection (1009) that sends a message longer than this.
WEBSOCKET_MAX_SIZE = 2 << 20
#: An idle connection's close handshake gets this long [s] before the socket is dropped.
IDLE_CLOSE_GRACE_S = 1.0


class _CloseRequested(Exception):
    """The client asked to close (Engine.IO close or Socket.IO disconnect)."""

    def __init__(self, disconnect: bool) -> None:
        super().__init__()
        #: Socket.IO's DISCONNECT: the client sends its Engine.IO close next
        self.disconnect = disconnect


#: The connection whose message is being handled (each handler task sets its own).
_CONNECTION: contextvars.ContextVar[Connection] = contextvars.ContextVar("drive_connection")


class DriveServer:
    """Serve ``policy`` to the Udacity simulator (or any client speaking its protocol).

    ``serve_forever()`` blocks (Ctrl-C stops it); ``start()`` serves from a background thread
    and returns the bound port (useful with ``port=0``), ``stop()`` ends it. Policy calls run
    one at a time on a worker thread, so the event loop keeps answering pings meanwhile.
    ``image_folder``: save each received frame as ``YYYY_MM_DD_HH_MM_SS_mmm.jpg`` (UTC), the
    JPEG bytes as received. Settings come from ``config`` (a :class:`DriveServerConfig`), with
    any of its fields overridden by keyword (``DriveServer(policy, port=0)``).
    """

    def __init__(self, policy: Policy, config: DriveServerConfig | None = None,
                 **options: object) -> None:
        if "image_folder" in options and options["image_folder"] is not None:
            options["image_folder"] = os.fspath(options["image_folder"])
        config = replace(config or DriveServerConfig(), **options)
        self.config = config
        self.policy = policy
        self.host = config.host
        self.port = config.port
        self.image_folder = Path(config.image_folder) if config.image_folder is not None else None
        self._frames = (FrameFolder(self.image_folder, config.image_folder_max_mb)
                        if self.image_folder is not None else None)
        self.status_interval_s = config.status_interval_s
        self.max_message_bytes = config.max_message_bytes
        self.max_connections = config.max_connections
        self._stats = DriveStats()
        self._executor: concurrent.futures.ThreadPoolExecutor | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop_event: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._startup_error: BaseException | None = None

    # ------------------------------------------------------------------ running

    def serve_forever(self) -> None:
        """Serve until interrupted (KeyboardInterrupt propagates) or :meth:`stop` is called."""
        asyncio.run(self._main())

    def start(self, timeout_s: float = 10.0) -> int:
        """Serve from a daemon thread; returns the bound port once listening."""
        if self._thread is not None:
            raise RuntimeError("server already started")
        self._ready.clear()
        self._startup_error = None
        self._thread = threading.Thread(target=self._thread_main, name="drive-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout_s):
            raise TimeoutError(f"drive server did not start within {timeout_s} s")
        if self._startup_error is not None:
            self._thread.join()
            self._thread = None
            raise self._startup_error
        return self.port

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop serving (closing connections) and wait for the thread started by :meth:`start`."""
        loop, stop_event = self._loop, self._stop_event
        if loop is not None and stop_event is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(stop_event.set)
            except RuntimeError:  # the loop closed between the check and the call
                pass
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None

    def __enter__(self) -> DriveServer:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def stats(self) -> DriveStats:
        """A snapshot of the counters."""
        frames = self._frames
        saved, not_saved = (frames.saved, frames.over_cap) if frames is not None else (0, 0)
        return replace(self._stats, bad=dict(self._stats.bad), refused=dict(self._stats.refused),
                       frames_saved=saved, frames_not_saved=not_saved)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}{SOCKET_PATH}/?EIO=4&transport=websocket"

    def _thread_main(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as error:  # reported to start(), or logged if it came later
            if not self._ready.is_set():
                self._startup_error = error
                self._ready.set()
            else:
                logger.exception("drive server stopped with an error")

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop_event = asyncio.Event()
        if self._frames is not None:
            self._frames.prepare()
        self._executor = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="policy")
        status_task = None
        try:
            async with serve(
                self._handle_connection,
                self.host,
                self.port,
                process_request=self._check_request,
                max_size=WEBSOCKET_MAX_SIZE,
                max_queue=4,
                ping_interval=protocol.PING_INTERVAL_MS / 1000,
                ping_timeout=protocol.PING_TIMEOUT_MS / 1000,
            ) as server:
                self.port = _bound_port(server, self.port)
                logger.info("drive server listening on %s", self.url)
                if hasattr(self.policy, "driving_settings"):
                    logger.info("driving the model: %s%s",
                                self.policy.driving_settings().describe(),
                                "; speed head: the learned speed, capped by the set speed"
                                if getattr(self.policy, "speed_head", False) else "")
                if not self.config.loopback_only:
                    logger.warning("listening on %s: other machines can connect and drive",
                                   self.host)
                if self.image_folder is not None:
                    logger.info("saving received frames to %s", self.image_folder)
                self._ready.set()
                if self.status_interval_s > 0:
                    status_task = asyncio.create_task(self._report_status())
                await self._stop_event.wait()
        finally:
            if status_task is not None:
                status_task.cancel()
            self._executor.shutdown(wait=True)
            self._loop = None

    async def _report_status(self) -> None:
        previous_steer, previous_time = 0, time.monotonic()
        while True:
            await asyncio.sleep(self.status_interval_s)
            now, stats = time.monotonic(), self._stats
            rate = (stats.steer - previous_steer) / max(now - previous_time, 1e-9)
            previous_steer, previous_time = stats.steer, now
            logger.info(
                "drive: %d connected, %d steer (%.1f/s), %d manual, %d safe, %d bad, %d pings, "
                "%d NaN predictions; last steering %+.3f throttle %+.2f at %.1f mph",
                stats.active_connections,
                stats.steer,
                rate,
                stats.manual,
                stats.safe,
                stats.bad_total,
                stats.pings,
                stats.nan_predictions,
                stats.last_steering,
                stats.last_throttle,
                stats.last_speed_mph,
            )

    # ------------------------------------------------------------------ connections

    def _check_request(self, connection: ServerConnection, request: Request) -> Response | None:
        """Accept the upgrade (None) or answer it with the error :mod:`~.admission` gives; a
        refusal with a reason is counted and logged."""
        refused = refusal(request, self.config, self.port, self._stats.active_connections)
        if refused is None:
            return None
        if refused.reason is not None:
            count = self._stats.refused.get(refused.reason, 0) + 1
            self._stats.refused[refused.reason] = count
            if worth_logging(count):
                logger.warning("refused a connection from %s (%s, #%d): %s",
                               connection.remote_address, refused.reason, count, refused.detail)
        return connection.respond(refused.status, refused.detail + "\n")

    async def _handle_connection(self, websocket: ServerConnection) -> None:
        policy = policy_for_connection(self.policy)
        connection = Connection(uuid.uuid4().hex, policy, nan_predictions=nan_count(policy))
        _CONNECTION.set(connection)  # this task's own: the message handlers count into it
        self._stats.connections += 1
        self._stats.active_connections += 1
        logger.info("client connected from %s (sid %s)", websocket.remote_address,
                    connection.sid)
        try:
            await asyncio.get_running_loop().run_in_executor(self._executor, policy.reset)
            await self._serve_connection(websocket, connection)
        except ConnectionClosed as error:
            if error.sent is not None and error.sent.code == 1009:
                detail = f"message over {WEBSOCKET_MAX_SIZE} bytes; connection closed"
                self._bad("oversized", detail)
            else:
                logger.info("connection %s closed: %s", connection.sid, error)
        finally:
            self._stats.active_connections -= 1
            logger.info("client %s disconnected: %d steer, %d safe replies", connection.sid,
                        connection.steer, connection.safe)

    async def _serve_connection(self, websocket: ServerConnection,
                                connection: Connection) -> None:
        """Answer one connection's messages until it closes, asks to close, or goes idle: no
        telemetry for ``idle_timeout_s``, counting both waiting for a message and waiting to
        send a reply (a client that stops reading fills its send buffer)."""
        loop = asyncio.get_running_loop()
        idle_s = self.config.idle_timeout_s
        deadline = loop.time() + idle_s  # pushed back by each telemetry answered
        for frame in (protocol.open_frame(connection.sid), protocol.CONNECT_FRAME):
            if not await self._send_by(websocket, frame, deadline, connection):
                return
        while True:
            try:
                async with asyncio.timeout_at(deadline):
                    message = await websocket.recv()
            except TimeoutError:
                await self._close_idle(websocket, connection, f"no telemetry for {idle_s:g} s")
                return
            answered = connection.telemetry
            try:
                reply = await self._on_message(message)
            except _CloseRequested as request:
                if request.disconnect:
                    await self._await_engine_close(websocket)
                return
            if connection.telemetry > answered:
                deadline = loop.time() + idle_s
            if reply is not None and not await self._send_by(websocket, reply, deadline,
                                                             connection):
                return

    async def _send_by(self, websocket: ServerConnection, frame: str, deadline: float,
                       connection: Connection) -> bool:
        """Send ``frame``; False (the connection closed as idle) if it is not sent by
        ``deadline`` (loop time)."""
        try:
            async with asyncio.timeout_at(deadline):
                await websocket.send(frame)
        except TimeoutError:
            reason = f"no telemetry for {self.config.idle_timeout_s:g} s (it stopped reading)"
            await self._close_idle(websocket, connection, reason)
            return False
        return True

    async def _await_engine_close(self, websocket: ServerConnection) -> None:
        """After Socket.IO's DISCONNECT, read (for at most :data:`IDLE_CLOSE_GRACE_S`) until
        the client's Engine.IO close or its own closing: python-socketio's client sends both,
        and its sending thread fails on a socket closed between them."""
        try:
            async with asyncio.timeout(IDLE_CLOSE_GRACE_S):
                while await websocket.recv() != protocol.ENGINE_CLOSE:
                    pass
        except (TimeoutError, ConnectionClosed):
            pass

    async def _close_idle(self, websocket: ServerConnection, connection: Connection,
                          reason: str) -> None:
        """Close an idle connection: the close handshake if the client answers it within
        :data:`IDLE_CLOSE_GRACE_S`, else the socket is dropped."""
        self._stats.idle_closed += 1
        logger.warning("closing connection %s: %s", connection.sid, reason)
        try:
            async with asyncio.timeout(IDLE_CLOSE_GRACE_S):
                await websocket.close(IDLE_CLOSE_CODE, reason[:100])
        except TimeoutError:
            websocket.transport.abort()

    # ------------------------------------------------------------------ messages

    async def _on_message(self, message: str | bytes) -> str | None:
        """The reply frame to one received message, or None for no reply."""
        self._stats.messages += 1
        what = triage(message, self.max_message_bytes)
        if what.outcome == TELEMETRY:
            return await self._on_telemetry(what.payload)
        if what.outcome == SAFE:
            return self._safe(what.reason, what.detail)
        if what.outcome == IGNORE:
            return self._ignore(what.reason, what.detail)
        if what.outcome == CLOSE:
            raise _CloseRequested(what.reason == DISCONNECT)
        if what.outcome == PING:
            self._stats.pings += 1
        elif what.outcome == MANUAL:
            self._stats.manual += 1
            _CONNECTION.get().telemetry += 1
            return protocol.MANUAL_FRAME
        return what.frame

    async def _on_telemetry(self, payload: object) -> str:
        try:
            telemetry = protocol.parse_telemetry(payload)
        except protocol.TelemetryError as error:
            return self._safe(error.reason, error.detail)
        loop = asyncio.get_running_loop()
        connection = _CONNECTION.get()
        try:
            steering, throttle, save_error = await loop.run_in_executor(
                self._executor, self._drive, connection.policy, telemetry
            )
            reply = protocol.steer_frame(steering, throttle, telemetry.decimal_separator)
        except protocol.TelemetryError as error:
            return self._safe(error.reason, error.detail)
        except Exception as error:  # a failing policy must not take the server down
            logger.exception("policy failed on a telemetry frame")
            return self._safe("policy_error", f"{type(error).__name__}: {error}")
        if save_error is not None:
            self._bad("save_error", save_error)
        self._count_nan_predictions(connection)
        stats = self._stats
        stats.steer += 1
        connection.steer += 1
        connection.telemetry += 1
        stats.last_steering, stats.last_throttle = steering, throttle
        stats.last_speed_mph = telemetry.speed_mph
        return reply

    def _drive(self, policy: Policy, telemetry: protocol.Telemetry
               ) -> tuple[float, float, str | None]:
        """Runs on the policy thread: decode, act, save the frame.

        Returns the controls and, if the frame could not be saved, why.
        """
        image_rgb = protocol.decode_image(telemetry.image_jpeg)
        steering, throttle = policy.act(image_rgb, telemetry.speed_mph)
        save_error = None
        if self._frames is not None:
            save_error = self._frames.save(telemetry.image_jpeg)
        return float(steering), float(throttle), save_error

    # ------------------------------------------------------------------ bookkeeping

    def _count_nan_predictions(self, connection: Connection) -> None:
        """Add the connection's new NaN predictions (a NetworkPolicy counts them) to the
        server's total; log them."""
        count = nan_count(connection.policy)
        if count <= connection.nan_predictions:
            return
        self._stats.nan_predictions += count - connection.nan_predictions
        connection.nan_predictions = count
        count = self._stats.nan_predictions
        if worth_logging(count):
            logger.warning("the model predicted NaN steering (%d frame(s) so far); "
                           "sent straight steering instead", count)

    def _bad(self, reason: str, detail: str) -> None:
        count = self._stats.bad.get(reason, 0) + 1
        self._stats.bad[reason] = count
        if worth_logging(count):
            logger.warning("bad message (%s, #%d): %s", reason, count, detail)

    def _safe(self, reason: str, detail: str) -> str:
        self._bad(reason, detail + " -> safe command")
        self._stats.safe += 1
        connection = _CONNECTION.get(None)
        if connection is not None:
            connection.safe += 1
        return protocol.SAFE_STEER_FRAME

    def _ignore(self, reason: str, detail: str) -> None:
        self._bad(reason, detail + " -> ignored")
        self._stats.ignored += 1
        return None


def _bound_port(server: Server, requested: int) -> int:
    for sock in server.sockets:
        return int(sock.getsockname()[1])
    return requested
