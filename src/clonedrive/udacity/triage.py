"""What each message a drive server receives calls for, decided before anything is driven.

What gets which answer:

* ``42["telemetry",{...}]`` -> ``steer`` with the policy's controls;
* ``42["telemetry",null]`` (manual mode) -> ``42["manual",{}]``;
* a frame that starts with ``42`` but cannot be used -- not JSON, missing or non-numeric fields,
  invalid base64, not a JPEG, corrupt JPEG, wrong image size, larger than
  ``max_message_bytes`` -- is logged, counted and answered with the safe command
  ``42["steer",{"steering_angle":"0","throttle":"0"}]`` so the simulator's loop keeps going;
* ping ``2<data>`` -> pong ``3<data>`` (``2probe`` -> ``3probe``); CONNECT ``40`` -> ``40``;
  close ``1`` or DISCONNECT ``41`` -> the connection is closed;
* anything else (binary frames, text that is not Engine.IO, events other than ``telemetry``) is
  logged, counted and ignored: answering it would break the lock-step of a real client.

:func:`triage` sorts a message into one of these outcomes from its framing alone (the fields
of a telemetry payload and its image are checked later, where the policy runs). It keeps no
state and counts nothing, so the rules read top to bottom in one place; the server acts on the
outcome and keeps the counts.
"""

from __future__ import annotations

from dataclasses import dataclass

from clonedrive.udacity import protocol

#: Outcomes of :func:`triage`.
ANSWER = "answer"  #: send ``frame`` (None: send nothing)
PING = "ping"  #: an Engine.IO ping: send ``frame``, the pong
CLOSE = "close"  #: the client asked to close (Engine.IO close or Socket.IO disconnect)
#: A CLOSE's reason when it was Socket.IO's DISCONNECT: the client's Engine.IO close follows.
DISCONNECT = "disconnect"
MANUAL = "manual"  #: telemetry null: the simulator is in manual mode
TELEMETRY = "telemetry"  #: a telemetry event: drive with ``payload``
SAFE = "safe"  #: a telemetry-like frame that cannot be used: the safe command
IGNORE = "ignore"  #: log it, count it, answer nothing


@dataclass(frozen=True)
class Triage:
    """What one received message calls for."""

    outcome: str  #: one of the outcomes above
    frame: str | None = None  #: ANSWER, PING: the reply frame
    payload: object = None  #: TELEMETRY: the event's first argument
    reason: str = ""  #: SAFE, IGNORE: the counted reason; CLOSE: DISCONNECT or ""
    detail: str = ""  #: SAFE, IGNORE: what was wrong, for the log


def triage(message: str | bytes, max_message_bytes: int) -> Triage:
    """What ``message`` (one WebSocket message) calls for; frames over ``max_message_bytes``
    are refused unread beyond their size."""
    if isinstance(message, bytes):
        return Triage(IGNORE, reason="binary", detail=f"binary frame of {len(message)} bytes")
    telemetry_like = message.startswith("42")
    if len(message) > max_message_bytes:
        detail = f"frame of {len(message)} bytes (limit {max_message_bytes})"
        return Triage(SAFE if telemetry_like else IGNORE, reason="oversized", detail=detail)
    try:
        engine = protocol.decode_engine_packet(message)
    except protocol.ProtocolError as error:
        return Triage(IGNORE, reason="garbage", detail=str(error))
    if engine.type == protocol.ENGINE_PING:
        return Triage(PING, frame=protocol.ENGINE_PONG + engine.data)
    if engine.type in (protocol.ENGINE_PONG, protocol.ENGINE_UPGRADE, protocol.ENGINE_NOOP):
        return Triage(ANSWER)
    if engine.type == protocol.ENGINE_CLOSE:
        return Triage(CLOSE)
    if engine.type == protocol.ENGINE_OPEN:
        return Triage(IGNORE, reason="garbage", detail="a client does not send Engine.IO open")
    return _triage_socket(engine.data, telemetry_like)


def _triage_socket(data: str, telemetry_like: bool) -> Triage:
    """What a Socket.IO packet (an Engine.IO message's data) calls for."""
    try:
        packet = protocol.decode_socket_packet(data)
    except protocol.ProtocolError as error:
        if telemetry_like:
            return Triage(SAFE, reason="not_json", detail=str(error))
        return Triage(IGNORE, reason="garbage", detail=str(error))
    if packet.namespace != protocol.DEFAULT_NAMESPACE:
        return Triage(IGNORE, reason="namespace",
                      detail=f"namespace {packet.namespace!r} is not served")
    if packet.type == protocol.SOCKET_CONNECT:
        return Triage(ANSWER, frame=protocol.CONNECT_FRAME)
    if packet.type == protocol.SOCKET_DISCONNECT:
        return Triage(CLOSE, reason=DISCONNECT)
    if packet.type != protocol.SOCKET_EVENT:
        return Triage(IGNORE, reason="garbage",
                      detail=f"Socket.IO packet type {packet.type} not handled")
    try:
        name, args = protocol.event_of(packet)
    except protocol.ProtocolError as error:
        return Triage(SAFE, reason="bad_event", detail=str(error))
    if name != "telemetry":
        return Triage(IGNORE, reason="unknown_event", detail=f"event {name!r} is not handled")
    payload = args[0] if args else None
    if payload is None:
        return Triage(MANUAL)
    return Triage(TELEMETRY, payload=payload)
