"""The drive server over a real socket, with a client that sends what the Udacity simulator sends.

The client connects to ``/socket.io/?EIO=4&transport=websocket`` without compression, never sends
the Socket.IO CONNECT (``40``), and sends ``42["telemetry",{...}]`` with string values and a
base64 320x160 JPEG -- a frame recorded by the real simulator.
"""

from __future__ import annotations

import asyncio
import base64
import json
import re
import time
from pathlib import Path

import numpy as np
import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, ConnectionClosedError, InvalidStatus

from clonedrive.base.images import read_rgb
from clonedrive.drivers.policy import NetworkPolicy, load_policy
from clonedrive.udacity import protocol
from clonedrive.udacity.server import DriveServer

NUMBER = r"(-?\d+(?:\.\d+)?)"
STEER = re.compile(
    r'42\["steer",\{"steering_angle":"' + NUMBER + r'","throttle":"' + NUMBER + r'"\}\]'
)
HANDSHAKE = re.compile(
    r'0\{"sid":"[0-9a-f]{32}","upgrades":\[\],"pingTimeout":60000,"pingInterval":25000\}'
)
SAFE = '42["steer",{"steering_angle":"0","throttle":"0"}]'
TIMEOUT_S = 10.0


def simulator_frame(image_jpeg: bytes, speed: str = "0.0000") -> str:
    """Byte for byte the simulator's telemetry event (N4 strings, base64 JPEG, no spaces)."""
    image = base64.b64encode(image_jpeg).decode("ascii")
    return (
        '42["telemetry",{"steering_angle":"0.0000","throttle":"0.0000",'
        f'"speed":"{speed}","image":"{image}"}}]'
    )


class RecordingPolicy:
    """A policy that remembers what it was given and answers fixed controls."""

    def __init__(self, steering: float = 0.25, throttle: float = 0.5) -> None:
        self.steering, self.throttle = steering, throttle
        self.images: list[np.ndarray] = []
        self.speeds: list[float] = []
        self.resets = 0
        self.fail = False

    def reset(self) -> None:
        self.resets += 1

    def act(self, image_rgb: np.ndarray, speed_mph: float) -> tuple[float, float]:
        if self.fail:
            raise RuntimeError("policy failure for the test")
        self.images.append(image_rgb.copy())
        self.speeds.append(speed_mph)
        return self.steering, self.throttle


def run_client(port: int, script, *, query: str = "EIO=4&transport=websocket"):
    """Connect like the simulator, read the handshake, run ``script(ws, handshake)``."""

    async def main():
        url = f"ws://127.0.0.1:{port}/socket.io/?{query}"
        async with connect(url, compression=None, open_timeout=TIMEOUT_S) as ws:
            handshake = [await receive(ws), await receive(ws)]
            return await script(ws, handshake)

    return asyncio.run(main())


async def receive(ws: ClientConnection) -> str:
    return await asyncio.wait_for(ws.recv(), TIMEOUT_S)


async def exchange(ws: ClientConnection, frame: str | bytes) -> str:
    await ws.send(frame)
    return await receive(ws)


async def assert_silent(ws: ClientConnection, seconds: float = 0.2) -> None:
    with pytest.raises(TimeoutError):
        await asyncio.wait_for(ws.recv(), seconds)


def parse_steer(reply: str) -> tuple[float, float]:
    match = STEER.fullmatch(reply)
    assert match is not None, reply
    payload = json.loads(reply[2:])[1]
    assert all(isinstance(value, str) for value in payload.values())
    return float(match[1]), float(match[2])


def jpeg_of(image_rgb: np.ndarray) -> bytes:
    return protocol.encode_image(image_rgb, quality=95)


def test_handshake_steer_reply_and_lock_step(tiny_model_path: Path, tiny_model,
                                             recorded_jpeg: bytes) -> None:
    server = DriveServer(load_policy(tiny_model_path, set_speed_mph=9.0), port=0)
    reference = NetworkPolicy(tiny_model, set_speed_mph=9.0)
    image = protocol.decode_image(recorded_jpeg)
    speeds = ["0.0000", "3.2500", "8.1000", "9.0000", "11.7500"]

    async def script(ws, handshake):
        replies = [await exchange(ws, simulator_frame(recorded_jpeg, speed)) for speed in speeds]
        await assert_silent(ws)  # exactly one reply per telemetry
        return handshake, replies

    with server:
        handshake, replies = run_client(server.port, script)
    assert HANDSHAKE.fullmatch(handshake[0])
    assert handshake[1] == "40"
    for speed, reply in zip(speeds, replies, strict=True):
        steering, throttle = parse_steer(reply)
        want_steering, want_throttle = reference.act(image, float(speed))
        assert steering == pytest.approx(want_steering, abs=1e-6)
        assert throttle == pytest.approx(want_throttle, abs=1e-6)
    # drive.py's PI by hand for the first two: e=9, sum=9; then e=5.75, sum=14.75.
    assert parse_steer(replies[0])[1] == pytest.approx(0.1 * 9 + 0.002 * 9)
    assert parse_steer(replies[1])[1] == pytest.approx(0.1 * 5.75 + 0.002 * 14.75)
    stats = server.stats()
    assert (stats.steer, stats.safe, stats.bad_total) == (5, 0, 0)


def test_manual_mode_ping_and_connect(recorded_jpeg: bytes) -> None:
    policy = RecordingPolicy()

    async def script(ws, handshake):
        return [
            await exchange(ws, '42["telemetry",null]'),
            await exchange(ws, "2"),
            await exchange(ws, "2probe"),
            await exchange(ws, "40"),
            await exchange(ws, simulator_frame(recorded_jpeg)),
        ]

    with DriveServer(policy, port=0) as server:
        replies = run_client(server.port, script)
        stats = server.stats()
    assert replies[:4] == ['42["manual",{}]', "3", "3probe", "40"]
    assert replies[4] == '42["steer",{"steering_angle":"0.25","throttle":"0.5"}]'
    assert len(policy.images) == 1  # manual mode does not call the policy
    assert (stats.manual, stats.pings, stats.steer) == (1, 2, 1)


def test_eio3_is_accepted_and_wrong_requests_are_refused(recorded_jpeg: bytes) -> None:
    async def script(ws, handshake):
        return await exchange(ws, simulator_frame(recorded_jpeg))

    async def refused(path: str) -> int:
        with pytest.raises(InvalidStatus) as caught:
            async with connect(f"ws://127.0.0.1:{server.port}{path}", open_timeout=TIMEOUT_S):
                pass
        return caught.value.response.status_code

    with DriveServer(RecordingPolicy(), port=0) as server:
        assert STEER.fullmatch(run_client(server.port, script, query="EIO=3&transport=websocket"))
        assert asyncio.run(refused("/other/?EIO=4&transport=websocket")) == 404
        assert asyncio.run(refused("/socket.io/?EIO=4&transport=polling")) == 400
        assert asyncio.run(refused("/socket.io/?EIO=2&transport=websocket")) == 400


def test_policy_receives_rgb(recorded_jpeg: bytes) -> None:
    """The classic bug: OpenCV decodes BGR. A frame whose left half is red must arrive red."""
    frame = np.zeros((160, 320, 3), dtype=np.uint8)
    frame[:, :160] = (255, 0, 0)  # RGB red
    policy = RecordingPolicy()

    async def script(ws, handshake):
        return await exchange(ws, simulator_frame(jpeg_of(frame)))

    with DriveServer(policy, port=0) as server:
        run_client(server.port, script)
    received = policy.images[0]
    assert received.shape == (160, 320, 3) and received.dtype == np.uint8
    left = received[8:-8, 8:150].reshape(-1, 3).mean(axis=0)
    right = received[8:-8, 170:-8].reshape(-1, 3).mean(axis=0)
    assert left[0] > 240 and left[1] < 15 and left[2] < 15
    assert right.max() < 15


def test_model_sees_rgb_end_to_end(tmp_path: Path) -> None:
    """A saved model whose steering is mean(R) - mean(B) in [0, 1] units steers +0.5, not -0.5."""
    import keras
    from keras import layers

    inputs = keras.Input(shape=(160, 320, 3))
    x = layers.Rescaling(1.0 / 255.0)(inputs)
    x = layers.GlobalAveragePooling2D()(x)
    outputs = layers.Dense(1, use_bias=False)(x)
    model = keras.Model(inputs, outputs)
    model.layers[-1].set_weights([np.array([[1.0], [0.0], [-1.0]], dtype=np.float32)])
    path = tmp_path / "colour_probe.keras"
    model.save(path)
    frame = np.zeros((160, 320, 3), dtype=np.uint8)
    frame[:, :160] = (255, 0, 0)

    async def script(ws, handshake):
        return await exchange(ws, simulator_frame(jpeg_of(frame)))

    with DriveServer(load_policy(path), port=0) as server:
        steering, _ = parse_steer(run_client(server.port, script))
    assert steering == pytest.approx(0.5, abs=0.02)


def _bad_frames(jpeg: bytes) -> dict[str, str]:
    good = base64.b64encode(jpeg).decode("ascii")
    small = base64.b64encode(jpeg_of(np.zeros((32, 64, 3), dtype=np.uint8))).decode("ascii")
    corrupt = base64.b64encode(jpeg[: len(jpeg) // 2]).decode("ascii")
    not_jpeg = base64.b64encode(np.random.default_rng(0).bytes(3000)).decode("ascii")

    def telemetry(**fields: str) -> str:
        payload = {"steering_angle": "0.0000", "throttle": "0.0000", "speed": "1.0000"}
        payload["image"] = good
        payload.update(fields)
        return protocol.encode_event("telemetry", payload)

    return {
        "invalid_base64": telemetry(image="@@not base64!!"),
        "corrupt_jpeg": telemetry(image=corrupt),
        "not_a_jpeg": telemetry(image=not_jpeg),
        "wrong_image_size": telemetry(image=small),
        "missing_field": '42["telemetry",{"steering_angle":"0.0000","throttle":"0.0000",'
        f'"image":"{good}"}}]',
        "non_numeric": telemetry(speed="fast"),
        "not_finite": telemetry(throttle="1e999"),
        "not_json": '42["telemetry",{"speed":',
        "not_an_object": '42["telemetry",[1,2]]',
        "empty_event": "42[]",
        "oversized": telemetry(padding="x" * (1_200_000)),
    }


BAD_KINDS = {  # kind of bad frame -> the reason the server counts it under
    "invalid_base64": "bad_base64",
    "corrupt_jpeg": "image_corrupt",
    "not_a_jpeg": "image_not_jpeg",
    "wrong_image_size": "image_size",
    "missing_field": "missing_field",
    "non_numeric": "non_numeric",
    "not_finite": "non_numeric",
    "not_json": "not_json",
    "not_an_object": "not_object",
    "empty_event": "bad_event",
    "oversized": "oversized",
}


def test_bad_kinds_cover_the_frames() -> None:
    assert sorted(_bad_frames(b"")) == sorted(BAD_KINDS)


@pytest.mark.parametrize("kind", BAD_KINDS)
def test_bad_telemetry_gets_safe_reply_and_connection_survives(
    kind: str, recorded_jpeg: bytes
) -> None:
    bad = _bad_frames(recorded_jpeg)[kind]
    policy = RecordingPolicy()

    async def script(ws, handshake):
        return [
            await exchange(ws, bad),
            await exchange(ws, simulator_frame(recorded_jpeg)),
            await exchange(ws, bad),
            await exchange(ws, "2"),
        ]

    with DriveServer(policy, port=0) as server:
        replies = run_client(server.port, script)
        stats = server.stats()
    assert replies[0] == SAFE and replies[2] == SAFE
    assert parse_steer(replies[1]) == (0.25, 0.5)
    assert replies[3] == "3"
    assert len(policy.images) == 1
    assert stats.safe == 2 and stats.bad == {BAD_KINDS[kind]: 2}


def test_garbage_is_ignored_without_reply(recorded_jpeg: bytes) -> None:
    async def script(ws, handshake):
        for garbage in ["hello", "", "9xyz", '4["nope"]', b"\x00\x01binary", '42["other",{}]']:
            await ws.send(garbage)
        await assert_silent(ws)
        return await exchange(ws, simulator_frame(recorded_jpeg))

    with DriveServer(RecordingPolicy(), port=0) as server:
        reply = run_client(server.port, script)
        stats = server.stats()
    assert parse_steer(reply) == (0.25, 0.5)
    assert stats.ignored == 6 and stats.steer == 1


def test_failing_policy_gets_safe_reply(recorded_jpeg: bytes) -> None:
    policy = RecordingPolicy()

    async def script(ws, handshake):
        policy.fail = True
        first = await exchange(ws, simulator_frame(recorded_jpeg))
        policy.fail = False
        return first, await exchange(ws, simulator_frame(recorded_jpeg))

    with DriveServer(policy, port=0) as server:
        first, second = run_client(server.port, script)
        stats = server.stats()
    assert first == SAFE
    assert parse_steer(second) == (0.25, 0.5)
    assert stats.bad == {"policy_error": 1}


def test_message_over_websocket_limit_closes_only_that_connection(recorded_jpeg: bytes) -> None:
    async def too_big(ws, handshake):
        await ws.send('42["telemetry",{"image":"' + "A" * (3 << 20) + '"}]')
        with pytest.raises(ConnectionClosedError) as caught:
            await receive(ws)
        return caught.value.rcvd.code

    async def normal(ws, handshake):
        return await exchange(ws, simulator_frame(recorded_jpeg))

    with DriveServer(RecordingPolicy(), port=0) as server:
        assert run_client(server.port, too_big) == 1009
        assert parse_steer(run_client(server.port, normal)) == (0.25, 0.5)
        # The server counts the refused message when its session for that connection ends,
        # which may be just after the client has seen the close: wait for it (bounded).
        deadline = time.monotonic() + 10.0
        while server.stats().bad != {"oversized": 1} and time.monotonic() < deadline:
            time.sleep(0.05)
        stats = server.stats()
    assert stats.bad == {"oversized": 1}
    assert stats.connections == 2


@pytest.mark.parametrize("goodbye", ["41", "1"])
def test_disconnect_or_close_ends_the_session(goodbye: str) -> None:
    async def script(ws, handshake):
        await ws.send(goodbye)
        with pytest.raises(ConnectionClosed):
            await receive(ws)
        return ws.close_code

    policy = RecordingPolicy()
    with DriveServer(policy, port=0) as server:
        assert run_client(server.port, script) == 1000
        assert run_client(server.port, script) == 1000
    assert policy.resets == 2  # each connection starts a fresh episode



def test_after_a_socketio_disconnect_the_engineio_close_still_gets_through() -> None:
    """python-socketio's client sends DISCONNECT, then its Engine.IO close from another
    thread: the server keeps the socket open for that close (its sending thread once failed
    with a broken pipe)."""
    async def script(ws, handshake):
        await ws.send("41")
        await asyncio.sleep(0.2)  # the client's second thread, a moment later
        await ws.send("1")  # raises ConnectionClosed if the server closed after "41"
        with pytest.raises(ConnectionClosed):
            await receive(ws)
        return ws.close_code

    with DriveServer(RecordingPolicy(), port=0) as server:
        assert run_client(server.port, script) == 1000

def test_image_folder_saves_each_frame(tmp_path: Path, recorded_jpeg: bytes) -> None:
    folder = tmp_path / "run1"

    async def script(ws, handshake):
        for _ in range(4):
            await exchange(ws, simulator_frame(recorded_jpeg))
        await exchange(ws, '42["telemetry",null]')

    with DriveServer(RecordingPolicy(), port=0, image_folder=folder) as server:
        run_client(server.port, script)
    saved = sorted(folder.iterdir())
    assert len(saved) == 4
    for path in saved:
        assert re.fullmatch(r"\d{4}_\d{2}_\d{2}_\d{2}_\d{2}_\d{2}_\d{3}\.jpg", path.name)
        assert path.read_bytes() == recorded_jpeg
    assert read_rgb(saved[0]).shape == (160, 320, 3)


def test_port_in_use_is_reported_by_start() -> None:
    with DriveServer(RecordingPolicy(), port=0) as first:
        second = DriveServer(RecordingPolicy(), port=first.port)
        with pytest.raises(OSError):
            second.start()
    second.stop()  # harmless after a failed start
