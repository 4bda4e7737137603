"""Engine.IO 3 / Socket.IO framing and telemetry payloads, without sockets."""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest

from clonedrive.udacity import protocol


def test_open_frame_is_what_working_servers_send() -> None:
    frame = protocol.open_frame("abc")
    assert frame == '0{"sid":"abc","upgrades":[],"pingTimeout":60000,"pingInterval":25000}'


def test_engine_packets() -> None:
    assert protocol.decode_engine_packet("2probe") == protocol.EnginePacket("2", "probe")
    assert protocol.decode_engine_packet("3") == protocol.EnginePacket("3", "")
    assert protocol.encode_engine_packet("3", "probe") == "3probe"
    for garbage in ["", "x", "7", " 2"]:
        with pytest.raises(protocol.ProtocolError):
            protocol.decode_engine_packet(garbage)


def test_socket_packets() -> None:
    packet = protocol.decode_socket_packet('2["telemetry",null]')
    assert (packet.type, packet.namespace, packet.ack_id, packet.data) == (
        "2",
        "/",
        None,
        ["telemetry", None],
    )
    packet = protocol.decode_socket_packet('2/chat,12["x",1]')
    assert (packet.namespace, packet.ack_id, packet.data) == ("/chat", 12, ["x", 1])
    assert protocol.decode_socket_packet("0").data is None
    with pytest.raises(protocol.ProtocolError):
        protocol.decode_socket_packet('2["telemetry",{')
    with pytest.raises(protocol.ProtocolError):
        protocol.decode_socket_packet('["telemetry"]')
    with pytest.raises(protocol.ProtocolError):
        protocol.decode_socket_packet("5-[]")


def test_events_round_trip() -> None:
    frame = protocol.encode_event("steer", {"steering_angle": "0.1", "throttle": "0.2"})
    assert frame == '42["steer",{"steering_angle":"0.1","throttle":"0.2"}]'
    assert protocol.decode_event(frame) == ("steer", [{"steering_angle": "0.1", "throttle": "0.2"}])
    assert protocol.decode_event(protocol.TELEMETRY_MANUAL_FRAME) == ("telemetry", [None])
    assert protocol.encode_event("manual", {}) == protocol.MANUAL_FRAME
    for not_event in ["2", "40", "42[]", "42[3]", '43["x"]']:
        with pytest.raises(protocol.ProtocolError):
            protocol.decode_event(not_event)


@pytest.mark.parametrize(
    ("value", "text"),
    [(0.2, "0.2"), (-0.0123, "-0.0123"), (0.0, "0"), (-0.0, "0"), (1.0, "1"), (-1.0, "-1"),
     (1e-9, "0"), (-1e-9, "0"), (0.1234567, "0.123457"), (3.5e-5, "0.000035")],
)  # fmt: skip
def test_numbers_are_plain_decimal_strings(value: float, text: str) -> None:
    assert protocol.format_number(value) == text
    assert float(text) == pytest.approx(value, abs=5e-7)


def test_steer_frame_values_are_strings() -> None:
    frame = protocol.steer_frame(-0.0123, 0.2)
    assert frame == '42["steer",{"steering_angle":"-0.0123","throttle":"0.2"}]'
    assert protocol.SAFE_STEER_FRAME == protocol.steer_frame(0.0, 0.0)
    with pytest.raises(ValueError):
        protocol.steer_frame(float("nan"), 0.0)


def test_telemetry_round_trip(recorded_jpeg: bytes) -> None:
    frame = protocol.telemetry_frame(-3.25, 0.5, 12.0, recorded_jpeg)
    name, args = protocol.decode_event(frame)
    assert name == "telemetry"
    assert args[0]["steering_angle"] == "-3.2500" and args[0]["speed"] == "12.0000"
    telemetry = protocol.parse_telemetry(args[0])
    assert telemetry == protocol.Telemetry(-3.25, 0.5, 12.0, recorded_jpeg)


@pytest.mark.parametrize(
    ("text", "value"),
    [("0.0000", 0.0), ("3.447378E-06", 3.447378e-06), ("-12.5", -12.5), ("12,3456", 12.3456),
     (" 7 ", 7.0), (".5", 0.5), (4, 4.0), (2.5, 2.5)],
)  # fmt: skip
def test_telemetry_numbers(text: object, value: float) -> None:
    assert protocol.parse_number(text, "speed") == pytest.approx(value)


@pytest.mark.parametrize("text", ["", "fast", "nan", "inf", "1e999", "1_000", "1.2.3", "0x10", None,
                                  True, [1]])  # fmt: skip
def test_telemetry_numbers_rejected(text: object) -> None:
    with pytest.raises(protocol.TelemetryError) as caught:
        protocol.parse_number(text, "speed")
    assert caught.value.reason == "non_numeric"
    assert "speed" in str(caught.value)


def test_telemetry_payload_errors(recorded_jpeg: bytes) -> None:
    good = {
        "steering_angle": "0.0000",
        "throttle": "0.0000",
        "speed": "0.0000",
        "image": base64.b64encode(recorded_jpeg).decode(),
    }
    cases = {
        "not_object": [1],
        "missing_field": {k: v for k, v in good.items() if k != "speed"},
        "bad_base64": {**good, "image": "é$%"},
        "non_numeric": {**good, "throttle": "full"},
    }
    for reason, payload in cases.items():
        with pytest.raises(protocol.TelemetryError) as caught:
            protocol.parse_telemetry(payload)
        assert caught.value.reason == reason
    with_prefix = {**good, "image": "data:image/jpeg;base64," + good["image"]}
    assert protocol.parse_telemetry(with_prefix).image_jpeg == recorded_jpeg


def test_jpeg_size_from_header(recorded_jpeg: bytes) -> None:
    assert protocol.jpeg_size(recorded_jpeg) == (320, 160)
    other = protocol.encode_image(np.zeros((37, 91, 3), dtype=np.uint8))
    assert protocol.jpeg_size(other) == (91, 37)
    for bad in [b"", b"\xff\xd8", b"\x89PNG\r\n\x1a\n" + bytes(20), recorded_jpeg[:20]]:
        with pytest.raises(ValueError):
            protocol.jpeg_size(bad)


def test_decode_image_returns_rgb() -> None:
    frame = np.zeros((160, 320, 3), dtype=np.uint8)
    frame[:, :160] = (255, 0, 0)
    frame[:, 160:] = (0, 0, 255)
    decoded = protocol.decode_image(protocol.encode_image(frame, quality=95))
    assert decoded.dtype == np.uint8 and decoded.shape == (160, 320, 3)
    assert np.abs(decoded[10:-10, 10:150].astype(int) - (255, 0, 0)).max() < 20
    assert np.abs(decoded[10:-10, 170:-10].astype(int) - (0, 0, 255)).max() < 20


def test_decode_image_errors(recorded_jpeg: bytes) -> None:
    cases = {
        "image_not_jpeg": b"not a jpeg at all",
        "image_corrupt": recorded_jpeg[: len(recorded_jpeg) // 2],
        "image_size": protocol.encode_image(np.zeros((80, 160, 3), dtype=np.uint8)),
    }
    for reason, data in cases.items():
        with pytest.raises(protocol.TelemetryError) as caught:
            protocol.decode_image(data)
        assert caught.value.reason == reason


def test_huge_jpeg_header_is_refused_before_decoding() -> None:
    """A header claiming 60000x60000 pixels is rejected from the header, not allocated."""
    jpeg = bytearray(protocol.encode_image(np.zeros((16, 16, 3), dtype=np.uint8)))
    start = 2
    while jpeg[start + 1] not in (0xC0, 0xC1, 0xC2):
        start += 2 + int.from_bytes(jpeg[start + 2 : start + 4], "big")
    jpeg[start + 5 : start + 9] = (60000).to_bytes(2, "big") * 2
    with pytest.raises(protocol.TelemetryError) as caught:
        protocol.decode_image(bytes(jpeg))
    assert caught.value.reason == "image_size"
    assert "60000x60000" in str(caught.value)


def test_frames_are_ascii_json() -> None:
    frame = protocol.encode_event("telemetry", {"note": "é"})
    assert frame.isascii()
    assert json.loads(frame[2:]) == ["telemetry", {"note": "é"}]
