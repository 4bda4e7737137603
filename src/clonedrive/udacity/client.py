"""Our simulator as the Udacity simulator's client: it connects to a drive server (``clonedrive
drive`` or an unmodified Udacity ``drive.py``) and speaks exactly as the Unity simulator does.

What the Unity simulator sends (its ``CommandServer`` and the bundled socket.io component):

* it opens ``ws://HOST:PORT/socket.io/?EIO=4&transport=websocket`` -- a plain WebSocket, no
  HTTP polling, no compression -- and reads the server's Engine.IO open packet ``0{...}``;
* it never sends the Socket.IO CONNECT (``40``): python-socketio 4.x connects the default
  namespace on the Engine.IO connection by itself, so its events fire anyway;
* on open it sends one ``42["telemetry",{...}]`` (N4 strings, base64 JPEG of the center
  camera) and then exactly one more after every ``steer`` or ``manual`` it receives: the loop
  is lock-step, whoever sent what first. ``drive.py`` answers the connection with an unsolicited
  ``steer`` 0/0, so against it one extra command is always in flight and each reply lands one
  step later than the telemetry it answers -- as it does with the real simulator;
* in manual mode it sends ``42["telemetry",null]`` and expects ``manual``;
* it pings (``2``) as soon as it is connected and then every ping interval, answers a server's
  ping with ``3``, and on closing sends ``41`` and ``1``.

:class:`SimulatorClient` is that client, one control step per :meth:`~SimulatorClient.controls_for`
call; :func:`drive_autonomous` runs our simulator headless under a drive server's control.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import re
import socket
import time
from dataclasses import dataclass, field

import numpy as np

from clonedrive.base.udacity_spec import JPEG_QUALITY, MAX_WHEEL_ANGLE_DEG, PORT, SET_SPEED_MPH
from clonedrive.sim.engine import DEFAULT_RENDERER, check_renderer
from clonedrive.udacity import protocol
from clonedrive.world.vehicle import Controls, check_set_speed

logger = logging.getLogger("clonedrive.client")

#: What the Unity simulator sends on closing: a Socket.IO DISCONNECT, then an Engine.IO close.
CLOSE_FRAMES = ("41", "1")
#: The biggest frame accepted from a server; a steer event is ~60 bytes.
MAX_SERVER_FRAME_BYTES = 1 << 20


class DriveServerError(RuntimeError):
    """The drive server could not be reached, went silent, or broke the protocol."""


@dataclass(frozen=True)
class ClientConfig:
    host: str = "127.0.0.1"
    port: int = PORT
    #: Keep retrying a refused connection this long (drive.py listens only once its model
    #: is loaded, which takes a while).
    connect_timeout_s: float = 30.0
    reply_timeout_s: float = 30.0  #: a server that does not answer stalls the car: give up
    jpeg_quality: int = JPEG_QUALITY  #: the simulator's Texture2D.EncodeToJPG default
    #: Seconds between Engine.IO pings; None: the interval the server announced (25 s).
    ping_interval_s: float | None = None
    #: Telemetry events sent on open. The Unity socket.io component raises "open" both when
    #: the WebSocket opens and when the Engine.IO open packet arrives, so the simulator's
    #: CommandServer may send two; 1 keeps our loop strictly lock-step with the server.
    open_telemetry: int = 1

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 65535:
            raise ValueError(f"port must be in 0..65535, got {self.port}")
        for name in ("connect_timeout_s", "reply_timeout_s"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in 1..100, got {self.jpeg_quality}")
        if self.ping_interval_s is not None and not self.ping_interval_s >= 0:
            raise ValueError(f"ping_interval_s must be >= 0 or None, got {self.ping_interval_s}")
        if self.open_telemetry < 1:
            raise ValueError(f"open_telemetry must be >= 1, got {self.open_telemetry}")


@dataclass
class ClientStats:
    """What one session sent and received."""

    telemetry_sent: int = 0  # telemetry events with data
    manual_sent: int = 0  # telemetry null (manual mode)
    steer_replies: int = 0
    manual_replies: int = 0
    pings_sent: int = 0
    pongs_received: int = 0
    server_pings: int = 0  # pings the server sent (answered with a pong)
    server_connect: bool = False  # the server sent a Socket.IO CONNECT ("40")
    ignored: int = 0  # frames that were neither a reply nor Engine.IO chatter


class SimulatorClient:
    """One WebSocket session with a drive server, used one control step at a time.

    Use as a context manager (or call :meth:`connect` and :meth:`close`)::

        with SimulatorClient(ClientConfig(port=4567)) as client:
            controls = client.controls_for(image_rgb, steering, throttle, speed_mph)
    """

    def __init__(self, config: ClientConfig | None = None) -> None:
        self.config = config or ClientConfig()
        self.stats = ClientStats()
        self.handshake: dict = {}
        self.last_frame: str | None = None  # the last event frame received, as sent
        self._exit_stack: contextlib.ExitStack | None = None
        self._socket = None
        self._ping_interval_s = protocol.PING_INTERVAL_MS / 1000.0
        self._next_ping_s = 0.0

    @property
    def url(self) -> str:
        return (f"ws://{self.config.host}:{self.config.port}/socket.io/"
                "?EIO=4&transport=websocket")

    @property
    def replies(self) -> int:
        """Replies received (steer and manual)."""
        return self.stats.steer_replies + self.stats.manual_replies

    @property
    def manual_replies(self) -> int:
        return self.stats.manual_replies

    @property
    def ping_interval_s(self) -> float:
        """The interval this session pings at (the server's, unless the config overrides it)."""
        return self._ping_interval_s

    def __enter__(self) -> SimulatorClient:
        self.connect()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ------------------------------------------------------------------ session

    def connect(self) -> None:
        """Open the WebSocket (retrying a refused connection until ``connect_timeout_s``) and
        read the server's Engine.IO open packet. Sends nothing: telemetry goes out with the
        first :meth:`controls_for`."""
        from websockets.exceptions import InvalidHandshake, InvalidStatus
        from websockets.sync.client import connect

        if self._socket is not None:
            raise RuntimeError("already connected")
        stack = contextlib.ExitStack()
        try:
            tcp = self._open_tcp()
            try:
                # Our own TCP socket: no proxy from the environment, as for the simulator.
                # No compression and no WebSocket-level pings: the simulator sends neither.
                websocket = connect(self.url, sock=tcp, compression=None, ping_interval=None,
                                    open_timeout=self.config.connect_timeout_s,
                                    max_size=MAX_SERVER_FRAME_BYTES, user_agent_header=None)
            except InvalidStatus as error:
                tcp.close()
                status = error.response.status_code
                raise DriveServerError(
                    f"the drive server at {self.url} refused the WebSocket (HTTP {status}); "
                    "python-engineio >= 3.14 refuses the Udacity simulator, use 3.13.2 or "
                    "`clonedrive drive`") from None
            except (InvalidHandshake, OSError, TimeoutError) as error:
                tcp.close()
                raise DriveServerError(
                    f"WebSocket handshake with {self.url} failed: {error}") from None
            self._socket = stack.enter_context(websocket)
            frame = self._recv()
            packet = self._decode(frame)
            if packet is None or packet.type != protocol.ENGINE_OPEN:
                raise DriveServerError(
                    f"expected the Engine.IO open packet, got {_preview(frame)}")
            self._read_handshake(packet.data)
        except BaseException:
            self._socket = None
            stack.close()
            raise
        self._exit_stack = stack
        self._next_ping_s = time.monotonic()  # the simulator pings as soon as it is connected

    def _open_tcp(self) -> socket.socket:
        deadline = time.monotonic() + self.config.connect_timeout_s
        while True:
            try:
                return socket.create_connection((self.config.host, self.config.port),
                                                timeout=self.config.connect_timeout_s)
            except OSError as error:  # server not up yet: retry until the deadline
                if time.monotonic() >= deadline:
                    raise DriveServerError(
                        f"cannot connect to {self.url}: {error} (is a drive server running? "
                        "start one with `clonedrive drive MODEL`)") from None
                time.sleep(0.2)

    def _read_handshake(self, data: str) -> None:
        try:
            handshake = json.loads(data)
            interval_ms = float(handshake["pingInterval"])
        except (json.JSONDecodeError, KeyError, TypeError, ValueError):
            logger.warning("open packet without a usable handshake: %s", _preview(data))
            handshake, interval_ms = {}, float(protocol.PING_INTERVAL_MS)
        self.handshake = handshake if isinstance(handshake, dict) else {}
        if self.config.ping_interval_s is not None:
            self._ping_interval_s = float(self.config.ping_interval_s)
        elif math.isfinite(interval_ms) and interval_ms > 0:
            self._ping_interval_s = interval_ms / 1000.0

    def close(self) -> None:
        """Say goodbye as the simulator does (``41``, ``1``) and close the WebSocket."""
        if self._socket is None:
            return
        from websockets.exceptions import ConnectionClosed

        try:
            for frame in CLOSE_FRAMES:
                self._socket.send(frame)
        except (ConnectionClosed, OSError):
            pass  # the server went first: nothing left to say
        finally:
            self._socket = None
            stack, self._exit_stack = self._exit_stack, None
            if stack is not None:
                stack.close()

    # ------------------------------------------------------------------ one control step

    def controls_for(self, image_rgb: np.ndarray, steering: float, throttle: float,
                     speed_mph: float) -> Controls | None:
        """Send one telemetry event for the car's state and wait for the server's reply.

        ``image_rgb``: the center camera, uint8 RGB (160, 320, 3); ``steering``: the applied
        steering in [-1, 1] (sent as the wheel angle in degrees); ``throttle``: the applied
        throttle (sent clipped to 0..1, as the simulator's AccelInput); ``speed_mph``.
        Returns the ``steer`` command, or ``None`` when the server answered ``manual``.
        """
        self._require_socket()
        self._ping_if_due()
        jpeg = protocol.encode_image(image_rgb, quality=self.config.jpeg_quality)
        throttle_sent = min(max(float(throttle), 0.0), 1.0)
        frame = protocol.telemetry_frame(float(steering) * MAX_WHEEL_ANGLE_DEG, throttle_sent,
                                         float(speed_mph), jpeg)
        first = self.stats.telemetry_sent + self.stats.manual_sent == 0
        for _ in range(self.config.open_telemetry if first else 1):
            self._send(frame)
            self.stats.telemetry_sent += 1
        return self._await_reply()

    def manual(self) -> Controls | None:
        """Send the manual-mode telemetry (``42["telemetry",null]``, a key held in the
        simulator) and wait for the reply: ``None`` for ``manual``, else the steer command."""
        self._require_socket()
        self._ping_if_due()
        first = self.stats.telemetry_sent + self.stats.manual_sent == 0
        for _ in range(self.config.open_telemetry if first else 1):
            self._send(protocol.TELEMETRY_MANUAL_FRAME)
            self.stats.manual_sent += 1
        return self._await_reply()

    def _require_socket(self) -> None:
        if self._socket is None:
            raise RuntimeError("not connected: call connect() or use the client as a context")

    def _ping_if_due(self) -> None:
        now = time.monotonic()
        if now >= self._next_ping_s:
            self._send(protocol.ENGINE_PING)
            self.stats.pings_sent += 1
            self._next_ping_s = now + self._ping_interval_s

    def _await_reply(self) -> Controls | None:
        """Read frames until a ``steer`` or ``manual`` event; answer pings meanwhile."""
        while True:
            frame = self._recv()
            packet = self._decode(frame)
            if packet is None:
                continue
            if packet.type == protocol.ENGINE_PING:  # an Engine.IO 4 server pings its clients
                self.stats.server_pings += 1
                self._send(protocol.ENGINE_PONG)
                continue
            if packet.type == protocol.ENGINE_PONG:
                self.stats.pongs_received += 1
                continue
            if packet.type == protocol.ENGINE_CLOSE:
                raise DriveServerError("the drive server closed the session (Engine.IO close)")
            if packet.type != protocol.ENGINE_MESSAGE:
                self._ignore(f"Engine.IO packet type {packet.type}", frame)
                continue
            reply = self._on_message(packet.data, frame)
            if reply is not None:
                return reply[0]

    def _on_message(self, data: str, frame: str) -> tuple[Controls | None] | None:
        """``(controls,)`` for a reply (controls None for ``manual``); None to keep reading."""
        try:
            packet = protocol.decode_socket_packet(data)
        except protocol.ProtocolError as error:
            self._ignore(str(error), frame)
            return None
        if packet.namespace != protocol.DEFAULT_NAMESPACE:
            self._ignore(f"namespace {packet.namespace!r}", frame)
            return None
        if packet.type == protocol.SOCKET_CONNECT:
            self.stats.server_connect = True
            return None
        if packet.type == protocol.SOCKET_DISCONNECT:
            raise DriveServerError("the drive server disconnected the session (Socket.IO 41)")
        if packet.type != protocol.SOCKET_EVENT:
            self._ignore(f"Socket.IO packet type {packet.type}", frame)
            return None
        try:
            name, args = protocol.event_of(packet)
        except protocol.ProtocolError as error:
            self._ignore(str(error), frame)
            return None
        self.last_frame = frame
        if name == "manual":
            self.stats.manual_replies += 1
            return (None,)
        if name == "steer":
            controls = parse_steer(args)
            self.stats.steer_replies += 1
            return (controls,)
        self._ignore(f"event {name!r}", frame)
        return None

    def _ignore(self, what: str, frame: str) -> None:
        self.stats.ignored += 1
        logger.info("ignoring %s from the drive server: %s", what, _preview(frame))

    # ------------------------------------------------------------------ frames

    def _send(self, frame: str) -> None:
        from websockets.exceptions import ConnectionClosed

        try:
            self._socket.send(frame)
        except (ConnectionClosed, OSError) as error:
            raise DriveServerError(f"connection to the drive server lost: {error}") from None

    def _recv(self) -> str:
        from websockets.exceptions import ConnectionClosed

        try:
            frame = self._socket.recv(timeout=self.config.reply_timeout_s)
        except TimeoutError:
            raise DriveServerError(
                f"the drive server sent nothing for {self.config.reply_timeout_s:g} s "
                "(a server that does not answer every telemetry stalls the car)") from None
        except (ConnectionClosed, OSError) as error:
            raise DriveServerError(f"connection to the drive server lost: {error}") from None
        if isinstance(frame, bytes):
            raise DriveServerError(f"the drive server sent a binary frame ({len(frame)} bytes)")
        return frame

    def _decode(self, frame: str) -> protocol.EnginePacket | None:
        try:
            return protocol.decode_engine_packet(frame)
        except protocol.ProtocolError as error:
            self._ignore(str(error), frame)
            return None


def parse_steer(args: list) -> Controls:
    """Controls from a ``steer`` event's arguments.

    The simulator reads each value with ``float.Parse(field.str)``: a JSON number has no
    ``.str``, so the real simulator silently stalls on it; we raise and say why instead.
    """
    if not args or not isinstance(args[0], dict):
        raise DriveServerError(f"steer event without a data object: {_preview(args)}")
    data = args[0]
    values = {}
    for key in ("steering_angle", "throttle"):
        raw = data.get(key)
        if not isinstance(raw, str):
            raise DriveServerError(
                f"steer field {key!r} is {raw!r}: the Udacity simulator needs it as a string")
        if not _REPLY_NUMBER.fullmatch(raw.strip()):  # Python's float() also takes "1_0", "nan"
            raise DriveServerError(f"steer field {key!r} is not a number: {_preview(raw)}")
        value = float(raw)
        if not math.isfinite(value):
            raise DriveServerError(f"steer field {key!r} is not finite: {raw!r}")
        values[key] = value
    return Controls(steering=values["steering_angle"], throttle=values["throttle"])


#: A number as the simulator's ``float.Parse`` reads a reply: digits, one decimal point, an
#: exponent; no digit separators ("1_0"), no words ("nan", "inf").
_REPLY_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")


def _preview(value: object, limit: int = 80) -> str:
    text = value if isinstance(value, str) else repr(value)
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text)} chars)"


# --------------------------------------------------------------------------- autonomous mode


class ServerDriver:
    """A drive server driving one car of the episode runner, as the Udacity simulator's
    autonomous mode: each step sends the center camera and the car's applied steering,
    throttle and speed, and applies the server's ``steer`` reply; a ``manual`` reply keeps the
    last command. The server cannot be told about interventions: its PI controller carries on.
    """

    def __init__(self, client: SimulatorClient) -> None:
        self.client = client
        self.controls = Controls()  #: the last command received

    def reset(self) -> None:
        self.controls = Controls()

    def act(self, obs) -> Controls:
        reply = self.client.controls_for(obs.images["center"], obs.steering, obs.throttle,
                                         obs.speed_mph)
        if reply is not None:  # "manual": keep the last command
            self.controls = reply
        return self.controls

    def intervened(self, obs) -> None:
        """Nothing to tell: the Udacity protocol has no message for it."""


@dataclass(frozen=True)
class AutonomousConfig:
    track: str = "lake"
    laps: int = 1
    #: The drive server's set speed [mph] as far as our side knows it: an intervention puts the
    #: car back at this speed, and the time limit follows from it (the episode runner's rules).
    #: drive.py and ``clonedrive drive`` hold 9 mph unless told otherwise.
    speed_mph: float = SET_SPEED_MPH
    #: Cap on simulated time [s] (default: the runner's time limit); steps = seconds x 15 Hz.
    max_seconds: float | None = None
    scenery: bool = True
    seed: int = 0  #: the scene's seed
    client: ClientConfig = field(default_factory=ClientConfig)
    renderer: str = DEFAULT_RENDERER  #: who draws the frames (sim/engine.py); whole frames

    def __post_init__(self) -> None:
        if not isinstance(self.track, str) or not self.track:
            raise ValueError(f"track must be a track name, got {self.track!r}")
        check_set_speed(self.speed_mph)
        check_renderer(self.renderer)
        self.episode_rules()  # laps >= 1, max_seconds > 0

    def episode_rules(self):
        from clonedrive.episode.rules import EpisodeRules

        return EpisodeRules(laps=self.laps, set_speed_mph=self.speed_mph,
                            max_seconds=self.max_seconds)


def drive_autonomous(config: AutonomousConfig, *, progress: bool = True) -> dict:
    """Let the drive server steer our car for ``laps`` laps; returns the run's metrics
    (the figures of ``clonedrive evaluate``, from the same episode runner) plus the session's
    counts. Each control step sends the center camera and the car's state, and applies the
    server's reply for one control period (1/15 s of simulated time). Leaving the road is an
    intervention: the car is put back on the centreline at ``speed_mph`` and the run goes on."""
    from clonedrive.base.progress import progress_bar
    from clonedrive.episode.runner import Episode, Step, drive
    from clonedrive.sim.simulator import SimConfig, Simulator

    sim_config = SimConfig(cameras=("center",), scenery=config.scenery, renderer=config.renderer)
    with Simulator(config.track, sim_config) as sim, SimulatorClient(config.client) as client:
        episode = Episode(sim, config.episode_rules(), track=config.track, seed=config.seed)
        length_m = sim.track.length_m
        bar = progress_bar(total=config.laps * round(length_m), unit="m", desc="autonomous",
                           enabled=progress)
        steps = 0

        def on_step(step: Step) -> None:
            nonlocal steps
            steps += 1
            obs = episode.observation
            covered_m = min(bar.total, round((episode.laps_started + obs.lap_progress) * length_m))
            bar.update(max(0, covered_m - bar.n))

        try:
            drive(episode, ServerDriver(client), on_step=on_step)
        finally:
            bar.close()
        summary = episode.trace.summary()
        summary["steps"] = steps
        summary["server_replies"] = client.replies
        summary["manual_replies"] = client.stats.manual_replies
        summary["telemetry_sent"] = client.stats.telemetry_sent
        summary["pings_sent"] = client.stats.pings_sent
        summary["server"] = client.url
        return summary
