"""The Udacity simulator's drive protocol: Engine.IO 3 / Socket.IO 2 text framing over a WebSocket.

The simulator (the client) opens ``ws://127.0.0.1:4567/socket.io/?EIO=4&transport=websocket``
and, despite ``EIO=4``, speaks Engine.IO protocol 3. Every WebSocket text frame is one Engine.IO
packet: a one-digit type followed by its data::

    0{"sid":...}   open (server -> client, once)     3    pong (answer to a ping, same data)
    1              close                             4... message: a Socket.IO packet follows
    2              ping (client -> server, 25 s)     5/6  upgrade / noop (ignored)

A Socket.IO packet (inside an Engine.IO message) is a one-digit type, an optional namespace
(``/name,``), an optional acknowledgement id (digits) and JSON data. The simulator only uses
events (``42["telemetry",{...}]``) in the default namespace and never sends CONNECT (``40``).

This module is pure framing (no sockets), shared by the drive server and by a client that plays
the simulator's part. Payload values are strings on the wire, both ways: see
:func:`telemetry_frame`, :func:`parse_telemetry` and :func:`steer_frame`.

Locales: the simulator formats telemetry with its machine's culture (C# ``ToString("N4")``) and
parses the reply with ``float.Parse`` in the same culture. On a comma-decimal machine (de-DE,
fr-FR, ...) the speed arrives as ``"12,3456"``, and a reply ``"-0.0123"`` would be read with
``.`` as a digit-group separator (-123). :func:`parse_telemetry` records which decimal separator
the telemetry used (:attr:`Telemetry.decimal_separator`) and :func:`steer_frame` answers with the
same one.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from clonedrive.base.images import ImageDecodeError, decode_rgb, jpeg_size
from clonedrive.base.udacity_spec import IMAGE_HEIGHT, IMAGE_WIDTH, JPEG_QUALITY

# Engine.IO packet types (protocol 3).
ENGINE_OPEN = "0"
ENGINE_CLOSE = "1"
ENGINE_PING = "2"
ENGINE_PONG = "3"
ENGINE_MESSAGE = "4"
ENGINE_UPGRADE = "5"
ENGINE_NOOP = "6"
ENGINE_TYPES = frozenset("0123456")

# Socket.IO packet types (protocol 4, as used by socket.io 2.x).
SOCKET_CONNECT = "0"
SOCKET_DISCONNECT = "1"
SOCKET_EVENT = "2"
SOCKET_ACK = "3"
SOCKET_ERROR = "4"
SOCKET_BINARY_EVENT = "5"
SOCKET_BINARY_ACK = "6"
SOCKET_TYPES = frozenset("0123456")

DEFAULT_NAMESPACE = "/"
#: Engine.IO ping interval / timeout the server announces, milliseconds.
PING_INTERVAL_MS = 25000
PING_TIMEOUT_MS = 60000

#: A Socket.IO CONNECT for the default namespace, as an Engine.IO message.
CONNECT_FRAME = "40"
#: What the simulator sends in manual mode, and what the server answers.
TELEMETRY_MANUAL_FRAME = '42["telemetry",null]'
MANUAL_FRAME = '42["manual",{}]'

_COMPACT = {"separators": (",", ":"), "ensure_ascii": True, "allow_nan": False}


class ProtocolError(ValueError):
    """A frame that is not valid Engine.IO / Socket.IO framing."""


class TelemetryError(ValueError):
    """A telemetry event whose payload cannot be used; ``reason`` is a short category key."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


# --------------------------------------------------------------------------- Engine.IO


@dataclass(frozen=True)
class EnginePacket:
    type: str  # one of ENGINE_*
    data: str


def decode_engine_packet(frame: str) -> EnginePacket:
    """Split a WebSocket text frame into its Engine.IO type and data."""
    if not frame or frame[0] not in ENGINE_TYPES:
        raise ProtocolError(f"not an Engine.IO packet: {_preview(frame)}")
    return EnginePacket(frame[0], frame[1:])


def encode_engine_packet(packet_type: str, data: str = "") -> str:
    if packet_type not in ENGINE_TYPES:
        raise ValueError(f"unknown Engine.IO packet type {packet_type!r}")
    return packet_type + data


def open_frame(
    sid: str, *, ping_interval_ms: int = PING_INTERVAL_MS, ping_timeout_ms: int = PING_TIMEOUT_MS
) -> str:
    """The server's first frame.

    ``0{"sid":...,"upgrades":[],"pingTimeout":60000,"pingInterval":25000}``
    """
    handshake = {
        "sid": sid,
        "upgrades": [],
        "pingTimeout": int(ping_timeout_ms),
        "pingInterval": int(ping_interval_ms),
    }
    return ENGINE_OPEN + json.dumps(handshake, **_COMPACT)


# --------------------------------------------------------------------------- Socket.IO


@dataclass(frozen=True)
class SocketPacket:
    type: str  # one of SOCKET_*
    namespace: str
    ack_id: int | None
    data: Any  # decoded JSON, or None when the packet carries none


_SOCKET_HEAD = re.compile(r"(?P<type>[0-6])(?:(?P<namespace>/[^,]*),)?(?P<ack>\d+)?")


def decode_socket_packet(data: str) -> SocketPacket:
    """Parse the data of an Engine.IO message as a Socket.IO packet."""
    head = _SOCKET_HEAD.match(data)
    if head is None:
        raise ProtocolError(f"not a Socket.IO packet: {_preview(data)}")
    if head["type"] in (SOCKET_BINARY_EVENT, SOCKET_BINARY_ACK):
        raise ProtocolError("binary Socket.IO packets are not supported")
    body = data[head.end() :]
    payload = None
    if body:
        try:
            payload = json.loads(body)
        except (json.JSONDecodeError, RecursionError) as error:
            raise ProtocolError(f"Socket.IO packet data is not JSON ({error})") from None
    ack = head["ack"]
    return SocketPacket(
        type=head["type"],
        namespace=head["namespace"] or DEFAULT_NAMESPACE,
        ack_id=int(ack) if ack is not None else None,
        data=payload,
    )


def encode_event(name: str, *args: Any, namespace: str = DEFAULT_NAMESPACE) -> str:
    """A complete frame for a Socket.IO event: ``42["name",arg,...]``."""
    prefix = ENGINE_MESSAGE + SOCKET_EVENT
    if namespace != DEFAULT_NAMESPACE:
        prefix += namespace + ","
    return prefix + json.dumps([name, *args], **_COMPACT)


def decode_event(frame: str) -> tuple[str, list[Any]]:
    """``(name, args)`` of a complete ``42[...]`` event frame; :class:`ProtocolError` otherwise."""
    engine = decode_engine_packet(frame)
    if engine.type != ENGINE_MESSAGE:
        raise ProtocolError(f"not an Engine.IO message: {_preview(frame)}")
    packet = decode_socket_packet(engine.data)
    if packet.type != SOCKET_EVENT:
        raise ProtocolError(f"not a Socket.IO event: {_preview(frame)}")
    return event_of(packet)


def event_of(packet: SocketPacket) -> tuple[str, list[Any]]:
    """``(name, args)`` of a decoded Socket.IO EVENT packet."""
    data = packet.data
    if not isinstance(data, list) or not data or not isinstance(data[0], str):
        raise ProtocolError("Socket.IO event data must be a JSON array starting with a name")
    return data[0], data[1:]


# --------------------------------------------------------------------------- payloads


#: The decimal separators a simulator's locale may use.
DECIMAL_SEPARATORS = (".", ",")


def _check_separator(decimal_separator: str) -> None:
    if decimal_separator not in DECIMAL_SEPARATORS:
        raise ValueError(f"decimal separator {decimal_separator!r}; expected '.' or ','")


def format_number(value: float, decimal_separator: str = ".") -> str:
    """A command value as the simulator parses it (``float.Parse``): plain decimal, no exponent.

    Six decimals at most, trailing zeros dropped: ``0.2``, ``-0.0123``, ``0``, ``1``; with
    ``decimal_separator=","`` (a comma-decimal simulator): ``0,2``, ``-0,0123``. No digit-group
    separators ever (values are at most a few units).
    """
    _check_separator(decimal_separator)
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"cannot send a non-finite value ({value})")
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    text = "0" if text in ("-0", "") else text
    return text.replace(".", decimal_separator)


def steer_frame(steering: float, throttle: float, decimal_separator: str = ".") -> str:
    """``42["steer",{"steering_angle":"<str>","throttle":"<str>"}]``; values are strings.

    ``decimal_separator``: the one the simulator's telemetry used
    (:attr:`Telemetry.decimal_separator`), so that its ``float.Parse`` reads the value right.
    """
    return encode_event(
        "steer",
        {
            "steering_angle": format_number(steering, decimal_separator),
            "throttle": format_number(throttle, decimal_separator),
        },
    )


#: The reply to telemetry that cannot be used: wheel straight, no throttle.
SAFE_STEER_FRAME = '42["steer",{"steering_angle":"0","throttle":"0"}]'


@dataclass(frozen=True)
class Telemetry:
    """One telemetry event as the simulator sends it (numbers arrive as strings)."""

    steering_angle_deg: float  # current wheel angle, degrees (+-25)
    throttle: float  # 0..1
    speed_mph: float
    image_jpeg: bytes  # the center camera, JPEG
    #: "," when the simulator's locale writes decimal commas (``"12,3456"``), else "."
    decimal_separator: str = "."


TELEMETRY_FIELDS = ("steering_angle", "throttle", "speed", "image")

_NUMBER = re.compile(r"[+-]?(?:\d+(?:[.,]\d*)?|[.,]\d+)(?:[eE][+-]?\d+)?")


def parse_number(text: Any, field: str) -> float:
    """A telemetry number: C# ``ToString`` output such as ``"0.0000"`` or ``"3.447378E-06"``.

    A comma decimal separator (``"12,3456"``, what a comma-decimal locale produces) is accepted;
    JSON numbers are accepted too. Anything else raises :class:`TelemetryError`.
    """
    if isinstance(text, bool):
        raise TelemetryError("non_numeric", f"field {field!r} is a boolean")
    if isinstance(text, int | float):
        value = float(text)
    elif isinstance(text, str) and _NUMBER.fullmatch(text.strip()):
        value = float(text.strip().replace(",", "."))
    else:
        raise TelemetryError("non_numeric", f"field {field!r} is not a number: {_preview(text)}")
    if not math.isfinite(value):
        raise TelemetryError("non_numeric", f"field {field!r} is not finite: {_preview(text)}")
    return value


_MAX_FIELD_PREVIEW = 60


def _preview(value: Any) -> str:
    text = value if isinstance(value, str) else repr(value)
    if len(text) > _MAX_FIELD_PREVIEW:
        return repr(text[:_MAX_FIELD_PREVIEW]) + f"... ({len(text)} chars)"
    return repr(text)


def parse_telemetry(payload: Any) -> Telemetry:
    """Validate the payload of a ``telemetry`` event (not ``null``: that is manual mode).

    Raises :class:`TelemetryError` with reason ``not_object``, ``missing_field``,
    ``non_numeric`` or ``bad_base64``. The image is checked to be base64 only; see
    :func:`decode_image` for the JPEG itself.
    """
    if not isinstance(payload, dict):
        raise TelemetryError("not_object", f"telemetry payload is {type(payload).__name__}")
    missing = [key for key in TELEMETRY_FIELDS if key not in payload]
    if missing:
        raise TelemetryError("missing_field", f"telemetry lacks {', '.join(missing)}")
    image = payload["image"]
    if not isinstance(image, str):
        raise TelemetryError("bad_base64", "field 'image' is not a string")
    if image.startswith("data:"):  # tolerate a data URL prefix
        image = image.partition(",")[2]
    try:
        jpeg = base64.b64decode(image, validate=True)
    except (binascii.Error, ValueError) as error:
        raise TelemetryError("bad_base64", f"field 'image' is not base64 ({error})") from None
    numbers = [payload[key] for key in ("steering_angle", "throttle", "speed")]
    return Telemetry(
        steering_angle_deg=parse_number(numbers[0], "steering_angle"),
        throttle=parse_number(numbers[1], "throttle"),
        speed_mph=parse_number(numbers[2], "speed"),
        image_jpeg=jpeg,
        decimal_separator=decimal_separator_of(numbers),
    )


def decimal_separator_of(texts: list[Any]) -> str:
    """``","`` if the simulator's numbers use decimal commas, else ``"."``.

    Comma when some value contains a comma and none a point: ``N4`` always writes four decimals
    (``"0,0000"``, ``"12,3456"``), and the values (angle in degrees, throttle, mph) never reach a
    thousand, so a comma there is never a digit-group separator.
    """
    strings = [text for text in texts if isinstance(text, str)]
    if any("," in text for text in strings) and not any("." in text for text in strings):
        return ","
    return "."


def telemetry_frame(
    steering_angle_deg: float,
    throttle: float,
    speed_mph: float,
    image_jpeg: bytes,
    decimal_separator: str = ".",
) -> str:
    """A telemetry event exactly as the simulator sends it (``N4`` strings, base64 JPEG).

    ``decimal_separator=","``: as a simulator on a comma-decimal machine sends it (``"12,3456"``).
    """
    _check_separator(decimal_separator)

    def n4(value: float) -> str:
        return f"{value:.4f}".replace(".", decimal_separator)

    payload = {
        "steering_angle": n4(steering_angle_deg),
        "throttle": n4(throttle),
        "speed": n4(speed_mph),
        "image": base64.b64encode(image_jpeg).decode("ascii"),
    }
    return encode_event("telemetry", payload)


# --------------------------------------------------------------------------- images

def decode_image(
    jpeg: bytes, *, width: int = IMAGE_WIDTH, height: int = IMAGE_HEIGHT
) -> np.ndarray:
    """Decode a JPEG to uint8 **RGB** ``(height, width, 3)``; :class:`TelemetryError` otherwise.

    Reasons: ``image_not_jpeg``, ``image_size`` (checked from the header before decoding, so a
    huge image is never allocated), ``image_corrupt``. OpenCV decodes to BGR; this returns RGB.
    """
    try:
        size = jpeg_size(jpeg)
    except ValueError as error:
        raise TelemetryError("image_not_jpeg", str(error)) from None
    if size != (width, height):
        raise TelemetryError(
            "image_size", f"image is {size[0]}x{size[1]}, expected {width}x{height}"
        )
    try:
        return decode_rgb(jpeg, name=f"JPEG of {len(jpeg)} bytes", shape=(height, width, 3))
    except ImageDecodeError as error:
        raise TelemetryError(error.reason, str(error)) from None


def encode_image(image_rgb: np.ndarray, *, quality: int = JPEG_QUALITY) -> bytes:
    """Encode uint8 RGB ``(H, W, 3)`` as JPEG (by default at the simulator's quality)."""
    import cv2

    if image_rgb.dtype != np.uint8 or image_rgb.ndim != 3 or image_rgb.shape[2] != 3:
        raise ValueError(f"expected uint8 (H, W, 3) RGB, got {image_rgb.dtype} {image_rgb.shape}")
    ok, buffer = cv2.imencode(
        ".jpg", cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
    )
    if not ok:
        raise ValueError("JPEG encoding failed")
    return buffer.tobytes()
