"""Our simulator as the Udacity simulator's client, against real drive servers on 127.0.0.1.

Three servers: our :class:`DriveServer` (in a thread), a server written the way Udacity's
``drive.py`` is on python-socketio 4.6.1 / python-engineio 3.13.2 / eventlet (in a subprocess:
eventlet must not monkey-patch this process), and -- end to end -- our DriveServer steering our
rendered car through ``drive_autonomous``.
"""

from __future__ import annotations

import base64
import io
import json
import math
import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from clonedrive.drivers.policy import NetworkPolicy
from clonedrive.sim.simulator import Controls
from clonedrive.udacity import protocol
from clonedrive.udacity.client import (
    AutonomousConfig,
    ClientConfig,
    DriveServerError,
    SimulatorClient,
    drive_autonomous,
    parse_steer,
)
from clonedrive.udacity.server import DriveServer

UDACITY_STYLE_SERVER = Path(__file__).with_name("udacity_style_server.py")
SERVER_START_TIMEOUT_S = 120.0  # the subprocess imports keras + torch and loads the model
STEER = re.compile(r'42\["steer",\{"steering_angle":"([^"]*)","throttle":"([^"]*)"\}\]')


def synthetic_frames(count: int, seed: int = 7) -> list[np.ndarray]:
    """Distinct 160x320 RGB frames: a sky/road-like gradient with a moving bright stripe."""
    rng = np.random.default_rng(seed)
    rows = np.linspace(0, 255, 160, dtype=np.float32)[:, None, None]
    frames = []
    for index in range(count):
        image = np.broadcast_to(rows, (160, 320, 3)).copy()
        image[:, :, 2] = 255 - image[:, :, 2]
        column = (index * 37) % 300
        image[70:150, column : column + 20, :] = 250
        image += rng.normal(0, 12, image.shape).astype(np.float32)
        frames.append(np.clip(image, 0, 255).astype(np.uint8))
    return frames


class FixedPolicy:
    """Answers fixed controls and remembers the speeds it was given."""

    def __init__(self, steering: float = -0.0125, throttle: float = 0.3) -> None:
        self.steering, self.throttle = steering, throttle
        self.speeds: list[float] = []
        self.shapes: list[tuple] = []

    def reset(self) -> None:
        pass

    def act(self, image_rgb: np.ndarray, speed_mph: float) -> tuple[float, float]:
        self.shapes.append(image_rgb.shape)
        self.speeds.append(speed_mph)
        return self.steering, self.throttle


def wait_until(condition, timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


# --------------------------------------------------------------------------- our DriveServer


@pytest.fixture(scope="module")
def frames() -> list[np.ndarray]:
    return synthetic_frames(20)


def test_lock_step_steps_against_our_drive_server(frames: list[np.ndarray]) -> None:
    policy = FixedPolicy()
    with DriveServer(policy, port=0, status_interval_s=0) as server:
        config = ClientConfig(port=server.port, ping_interval_s=0.0)  # a ping before each step
        with SimulatorClient(config) as client:
            assert client.handshake["pingInterval"] == 25000
            replies = [
                client.controls_for(frames[step], steering=0.1 * step, throttle=0.5,
                                    speed_mph=1.25 * step)
                for step in range(5)
            ]
            assert STEER.fullmatch(client.last_frame)  # values were strings on the wire
            stats = server.stats()
        assert replies == [Controls(steering=-0.0125, throttle=0.3)] * 5
        assert stats.steer == client.stats.telemetry_sent == 5  # one reply per telemetry
        assert stats.pings == client.stats.pings_sent == 5
        assert client.stats.pongs_received == 5
        assert client.stats.server_connect  # DriveServer sends "40" though we never do
        assert client.stats.ignored == 0
        assert policy.speeds == [0.0, 1.25, 2.5, 3.75, 5.0]  # "N4" strings parsed back
        assert policy.shapes == [(160, 320, 3)] * 5


def test_pings_follow_the_announced_interval_and_manual_mode(frames: list[np.ndarray]) -> None:
    with DriveServer(FixedPolicy(), port=0, status_interval_s=0) as server:
        with SimulatorClient(ClientConfig(port=server.port)) as client:
            assert client.ping_interval_s == 25.0  # from the server's open packet
            for step in range(4):
                client.controls_for(frames[step], 0.0, 0.0, 0.0)
            assert client.manual() is None  # telemetry null -> manual
            assert client.controls_for(frames[4], 0.0, 0.0, 0.0) == Controls(-0.0125, 0.3)
        stats = server.stats()
    assert client.stats.pings_sent == 1  # on connecting, as the simulator does; next in 25 s
    assert stats.pings == 1
    assert (stats.steer, stats.manual) == (5, 1)
    assert (client.stats.steer_replies, client.stats.manual_replies) == (5, 1)
    assert wait_until(lambda: server.stats().active_connections == 0)  # "41" then "1" closed it


def test_two_telemetry_on_open_keeps_one_extra_in_flight(frames: list[np.ndarray]) -> None:
    with DriveServer(FixedPolicy(), port=0, status_interval_s=0) as server:
        with SimulatorClient(ClientConfig(port=server.port, open_telemetry=2)) as client:
            for step in range(6):
                assert client.controls_for(frames[step], 0.0, 0.0, 0.0) is not None
            assert client.stats.telemetry_sent == 7
            assert client.stats.steer_replies == 6
            assert wait_until(lambda: server.stats().steer == 7)  # the extra one was answered


def test_no_server_is_a_clear_error(free_port: int) -> None:
    config = ClientConfig(port=free_port, connect_timeout_s=0.5)
    started = time.monotonic()
    with pytest.raises(DriveServerError, match="cannot connect"):
        SimulatorClient(config).connect()
    assert time.monotonic() - started < 5


def test_steer_values_must_be_strings() -> None:
    assert parse_steer([{"steering_angle": "-0.0123", "throttle": "0.2"}]) == Controls(
        steering=-0.0123, throttle=0.2)
    assert parse_steer([{"steering_angle": "1e-05", "throttle": "0"}]).steering == 1e-05
    with pytest.raises(DriveServerError, match="as a string"):
        parse_steer([{"steering_angle": 0.1, "throttle": "0.2"}])
    with pytest.raises(DriveServerError, match="not a number"):
        parse_steer([{"steering_angle": "nan", "throttle": "0.2"}])
    with pytest.raises(DriveServerError, match="not finite"):  # a number, too large for a float
        parse_steer([{"steering_angle": "1e400", "throttle": "0.2"}])
    with pytest.raises(DriveServerError, match="data object"):
        parse_steer([])


def test_config_is_checked() -> None:
    with pytest.raises(ValueError, match="open_telemetry"):
        ClientConfig(open_telemetry=0)
    with pytest.raises(ValueError, match="ping_interval_s"):
        ClientConfig(ping_interval_s=-1.0)
    with pytest.raises(ValueError, match="max_seconds"):
        AutonomousConfig(max_seconds=0)


# --------------------------------------------------------------------------- drive.py's stack


@pytest.fixture(scope="module")
def udacity_style_server(tiny_h5_path: Path, tmp_path_factory: pytest.TempPathFactory):
    """The drive.py-style server in a subprocess; yields its port."""
    model_path = tiny_h5_path
    log = tmp_path_factory.mktemp("udacity_log") / "server.out"
    env = dict(os.environ, KERAS_BACKEND="torch", PYTHONUNBUFFERED="1")
    with open(log, "w") as out:
        process = subprocess.Popen(
            [sys.executable, str(UDACITY_STYLE_SERVER), str(model_path), "0"],
            stdout=out, stderr=subprocess.STDOUT, env=env, cwd=model_path.parent)
    try:
        port = None
        deadline = time.monotonic() + SERVER_START_TIMEOUT_S
        while port is None:
            match = re.search(r"listening on 127\.0\.0\.1:(\d+)", log.read_text())
            if match:
                port = int(match[1])
            elif process.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"the drive.py-style server did not start:\n{log.read_text()}")
            else:
                time.sleep(0.1)
        yield port
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def expected_steer(model, jpeg: bytes, speeds_mph: list[float]) -> tuple[float, float]:
    """What drive.py computes for a frame: PIL decode, predict, PI on all speeds so far."""
    from PIL import Image

    pixels = np.asarray(Image.open(io.BytesIO(jpeg)))
    steering = float(model.predict(pixels[None], batch_size=1, verbose=0)[0][0])
    errors = [9.0 - speed for speed in speeds_mph]
    return steering, 0.1 * errors[-1] + 0.002 * sum(errors)


def test_drives_against_a_drive_py_style_python_socketio_4_server(
    udacity_style_server: int, tiny_model, frames: list[np.ndarray]
) -> None:
    model = tiny_model
    speeds = [0.5 * step for step in range(len(frames))]
    with SimulatorClient(ClientConfig(port=udacity_style_server)) as client:
        replies = [client.controls_for(frame, 0.0, 0.2, speed)
                   for frame, speed in zip(frames, speeds, strict=True)]
        # drive.py answers telemetry null with manual; one steer is still in flight first.
        in_flight = client.manual()
        assert client.manual() is None
        last_frame = client.last_frame
    assert all(reply is not None for reply in replies)
    # The server fired its handlers although we never sent "40": python-socketio 4 connects
    # the default namespace with the Engine.IO session, and its "40" came after the
    # connect handler's steer 0/0.
    assert client.stats.server_connect
    assert replies[0] == Controls(steering=0.0, throttle=0.0)  # drive.py's connect handler
    answers = [*replies[1:], in_flight]  # then one reply per telemetry, in order
    for step, (frame, reply) in enumerate(zip(frames, answers, strict=True)):
        jpeg = protocol.encode_image(frame, quality=75)  # the bytes the client sent
        want_steering, want_throttle = expected_steer(model, jpeg, speeds[: step + 1])
        assert reply.steering == pytest.approx(want_steering, abs=1e-6), step
        assert reply.throttle == pytest.approx(want_throttle, abs=1e-9), step
    assert len({round(reply.steering, 6) for reply in answers}) > 1  # frames told apart
    assert json.loads(last_frame[2:]) == ["manual", {}]
    assert client.stats.pings_sent == 1 and client.stats.pongs_received == 1
    assert client.stats.ignored == 0


def test_telemetry_frame_is_what_drive_py_decodes(frames: list[np.ndarray]) -> None:
    """The image field decodes with drive.py's own steps (base64 -> PIL) to our RGB frame."""
    from PIL import Image

    jpeg = protocol.encode_image(frames[0], quality=75)
    name, args = protocol.decode_event(protocol.telemetry_frame(-2.5, 0.2, 8.0, jpeg))
    payload = args[0]
    assert name == "telemetry"
    assert {key: payload[key] for key in ("steering_angle", "throttle", "speed")} == {
        "steering_angle": "-2.5000", "throttle": "0.2000", "speed": "8.0000"}
    pixels = np.asarray(Image.open(io.BytesIO(base64.b64decode(payload["image"]))))
    assert pixels.shape == (160, 320, 3)
    error = np.abs(pixels.astype(int) - frames[0]).mean()  # JPEG loses the noise a little
    swapped = np.abs(pixels.astype(int) - frames[0][:, :, ::-1]).mean()
    assert error < 12 < 5 * error < swapped  # RGB order kept (the BGR mix-up is far off)


# --------------------------------------------------------------------------- end to end


def test_drive_autonomous_end_to_end_with_our_drive_server(tiny_model) -> None:
    policy = NetworkPolicy(tiny_model, set_speed_mph=9.0)
    with DriveServer(policy, port=0, status_interval_s=0) as server:
        config = AutonomousConfig(track="lake", laps=1, max_seconds=3, scenery=False,
                                  client=ClientConfig(port=server.port))
        summary = drive_autonomous(config, progress=False)
        assert wait_until(lambda: server.stats().active_connections == 0)
        stats = server.stats()
    assert summary["steps"] == 45  # 3 s at 15 Hz
    assert summary["server_replies"] == summary["telemetry_sent"] == stats.steer == 45
    assert stats.bad_total == 0 and stats.safe == 0
    assert summary["track"] == "lake" and summary["laps_completed"] == 0
    assert summary["timed_out"] is True
    assert summary["elapsed_s"] == pytest.approx(3.0)
    for key in ("mean_abs_cte_m", "max_abs_cte_m", "smoothness", "mean_speed_mph",
                "distance_m", "autonomy_pct"):
        assert math.isfinite(summary[key]), key
    assert 0 < summary["mean_speed_mph"] < 12  # the PI controller drove toward 9 mph
    assert stats.last_speed_mph > 3


def test_drive_autonomous_under_the_drive_py_style_server(udacity_style_server: int) -> None:
    config = AutonomousConfig(track="lake", laps=1, max_seconds=2, scenery=False,
                              client=ClientConfig(port=udacity_style_server))
    summary = drive_autonomous(config, progress=False)
    assert summary["steps"] == summary["server_replies"] == summary["telemetry_sent"] == 30
    assert summary["manual_replies"] == 0
    assert summary["distance_m"] > 0  # drive.py's PI throttle moved the car
    assert math.isfinite(summary["mean_abs_cte_m"])


def test_a_server_refusing_the_websocket_is_named(tmp_path: Path) -> None:
    """python-engineio >= 3.14 answers the simulator's EIO=4 request with HTTP 400."""
    import threading

    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(1)

        def refuse() -> None:
            connection, _ = listener.accept()
            with connection:
                connection.recv(4096)
                connection.sendall(b"HTTP/1.1 400 BAD REQUEST\r\nContent-Length: 0\r\n"
                                   b"Connection: close\r\n\r\n")

        thread = threading.Thread(target=refuse, daemon=True)
        thread.start()
        config = ClientConfig(port=listener.getsockname()[1], connect_timeout_s=5)
        with pytest.raises(DriveServerError, match=r"HTTP 400.*python-engineio"):
            SimulatorClient(config).connect()
        thread.join(5)


@pytest.mark.parametrize("raw", ["1_0", "nan", "inf", "-Infinity", "0x1p-2", "1.0.0", "", " "])
def test_a_steer_reply_the_simulator_would_not_parse_is_refused(raw: str) -> None:
    """Python's float() reads "1_0" as 10.0; the simulator's parser would not."""
    from clonedrive.udacity.client import DriveServerError, parse_steer

    with pytest.raises(DriveServerError, match="not a number|not finite"):
        parse_steer([{"steering_angle": raw, "throttle": "0.2"}])


def test_a_plain_steer_reply_is_read() -> None:
    from clonedrive.udacity.client import parse_steer

    controls = parse_steer([{"steering_angle": "-0.125", "throttle": "3E-01"}])
    assert (controls.steering, controls.throttle) == (-0.125, 0.3)
