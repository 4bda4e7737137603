"""Comma-decimal simulators: the drive server answers in the locale the telemetry was written in.

The Udacity simulator writes telemetry with C# ``ToString("N4")`` and reads the reply with
``float.Parse``, both in the machine's culture. :func:`csharp_parse` below does what
``float.Parse`` does in en-US and de-DE (the default ``NumberStyles.Float | AllowThousands``:
the group separator is skipped, the decimal separator ends the integer part).
"""

from __future__ import annotations

import asyncio
import base64

import numpy as np
import pytest
from websockets.asyncio.client import connect

from clonedrive.udacity import protocol
from clonedrive.udacity.server import DriveServer

CULTURES = {"en-US": (".", ","), "de-DE": (",", ".")}  # culture -> (decimal, group separator)


def csharp_parse(text: str, culture: str) -> float:
    """``float.Parse(text, CultureInfo(culture))`` for plain decimal strings."""
    decimal, group = CULTURES[culture]
    return float(text.replace(group, "").replace(decimal, "."))


def simulator_frame(image_jpeg: bytes, culture: str) -> str:
    """Byte for byte what the simulator sends in ``culture``: angle -3.25 deg, throttle 0.2,
    12.3456 mph, as ``N4`` strings."""
    image = base64.b64encode(image_jpeg).decode("ascii")
    angle, throttle, speed = {
        "en-US": ("-3.2500", "0.2000", "12.3456"),
        "de-DE": ("-3,2500", "0,2000", "12,3456"),
    }[culture]
    return (
        f'42["telemetry",{{"steering_angle":"{angle}","throttle":"{throttle}",'
        f'"speed":"{speed}","image":"{image}"}}]'
    )


def test_the_old_reply_is_misread_by_a_comma_simulator() -> None:
    # Why this matters: "." is de-DE's group separator, so "-0.0123" reads as -123.
    assert csharp_parse("-0.0123", "de-DE") == -123.0
    assert csharp_parse("-0,0123", "de-DE") == pytest.approx(-0.0123)


@pytest.mark.parametrize("culture", ["en-US", "de-DE"])
def test_telemetry_records_its_decimal_separator(recorded_jpeg: bytes, culture: str) -> None:
    name, args = protocol.decode_event(simulator_frame(recorded_jpeg, culture))
    telemetry = protocol.parse_telemetry(args[0])
    assert name == "telemetry"
    assert telemetry.decimal_separator == CULTURES[culture][0]
    assert (telemetry.steering_angle_deg, telemetry.throttle, telemetry.speed_mph) == (
        pytest.approx(-3.25), pytest.approx(0.2), pytest.approx(12.3456))


def test_steer_and_telemetry_frames_in_both_locales(recorded_jpeg: bytes) -> None:
    assert protocol.steer_frame(-0.0123, 0.2) == (
        '42["steer",{"steering_angle":"-0.0123","throttle":"0.2"}]')
    assert protocol.steer_frame(-0.0123, 0.2, ",") == (
        '42["steer",{"steering_angle":"-0,0123","throttle":"0,2"}]')
    assert protocol.steer_frame(0.0, 1.0, ",") == (
        '42["steer",{"steering_angle":"0","throttle":"1"}]')
    # Our client can play a comma-locale simulator: the same bytes as the real one.
    assert protocol.telemetry_frame(-3.25, 0.2, 12.3456, recorded_jpeg, ",") == simulator_frame(
        recorded_jpeg, "de-DE")
    assert protocol.telemetry_frame(-3.25, 0.2, 12.3456, recorded_jpeg) == simulator_frame(
        recorded_jpeg, "en-US")
    with pytest.raises(ValueError, match="separator"):
        protocol.format_number(1.5, ";")


def test_ambiguous_numbers_default_to_a_point() -> None:
    assert protocol.decimal_separator_of(["0", "1", "2"]) == "."
    assert protocol.decimal_separator_of(["0,5", "1.5"]) == "."
    assert protocol.decimal_separator_of([0.5, "1,5"]) == ","


class FixedPolicy:
    def __init__(self) -> None:
        self.speeds: list[float] = []

    def reset(self) -> None:
        pass

    def act(self, image_rgb: np.ndarray, speed_mph: float) -> tuple[float, float]:
        self.speeds.append(speed_mph)
        return -0.0123, 0.2


def test_comma_locale_round_trip_over_a_socket(recorded_jpeg: bytes) -> None:
    """de-DE telemetry gets comma replies, en-US telemetry point replies, on one connection;
    each reply, read as that culture's float.Parse reads it, is the policy's controls."""
    policy = FixedPolicy()

    async def client(port: int) -> list[str]:
        url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
        async with connect(url, compression=None, open_timeout=10) as ws:
            await ws.recv()  # open
            await ws.recv()  # 40
            replies = []
            for culture in ("de-DE", "en-US", "de-DE"):
                await ws.send(simulator_frame(recorded_jpeg, culture))
                replies.append(await asyncio.wait_for(ws.recv(), 10))
            return replies

    with DriveServer(policy, port=0, status_interval_s=0) as server:
        replies = asyncio.run(client(server.port))
    assert replies[0] == replies[2] == '42["steer",{"steering_angle":"-0,0123","throttle":"0,2"}]'
    assert replies[1] == '42["steer",{"steering_angle":"-0.0123","throttle":"0.2"}]'
    for reply, culture in zip(replies, ("de-DE", "en-US", "de-DE"), strict=True):
        name, args = protocol.decode_event(reply)
        values = args[0]
        assert name == "steer"
        assert csharp_parse(values["steering_angle"], culture) == pytest.approx(-0.0123)
        assert csharp_parse(values["throttle"], culture) == pytest.approx(0.2)
    assert policy.speeds == [pytest.approx(12.3456)] * 3
