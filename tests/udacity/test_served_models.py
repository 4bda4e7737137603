"""Models as the drive server serves them: a student's Keras 2 Lambda model with --trust-model,
an ONNX model, and a model predicting NaN (counted and logged)."""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path

import keras
import numpy as np
import pytest
from keras import layers
from support.student_models import student_model, write_keras2_h5
from websockets.asyncio.client import connect

from clonedrive.cli import main
from clonedrive.drivers.policy import NetworkPolicy, load_policy
from clonedrive.udacity import protocol
from clonedrive.udacity.server import DriveServer

FIXTURE_IMAGES = Path(__file__).parents[1] / "fixtures" / "udacity" / "mountain_windows_paths"


@pytest.fixture(scope="module")
def jpegs() -> list[bytes]:
    paths = sorted((FIXTURE_IMAGES / "IMG").glob("center_*.jpg"))[::20][:3]
    return [path.read_bytes() for path in paths]


def serve(policy, jpegs: list[bytes]) -> tuple[list[str], object]:
    async def client(port: int) -> list[str]:
        url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
        async with connect(url, compression=None, open_timeout=10) as ws:
            await ws.recv()
            await ws.recv()
            replies = []
            for jpeg in jpegs:
                await ws.send(protocol.telemetry_frame(0.0, 0.0, 9.0, jpeg))
                replies.append(await asyncio.wait_for(ws.recv(), 30))
            return replies

    with DriveServer(policy, port=0, status_interval_s=0) as server:
        replies = asyncio.run(client(server.port))
        stats = server.stats()
    return replies, stats


def steering_of(reply: str) -> float:
    name, args = protocol.decode_event(reply)
    assert name == "steer"
    return float(args[0]["steering_angle"])


def test_a_students_keras2_model_is_served_with_trust(tmp_path: Path, jpegs, capsys) -> None:
    student = student_model(seed=8)
    path = write_keras2_h5(tmp_path / "model.h5", student)
    # Without the flag: one line that says what to do, no traceback.
    assert main(["drive", str(path), "--port", "0"]) == 1
    err = capsys.readouterr().err
    assert "--trust-model" in err and "Traceback" not in err
    replies, stats = serve(load_policy(path, trust=True), jpegs)
    want = NetworkPolicy(student).predict_steering(
        np.stack([protocol.decode_image(jpeg) for jpeg in jpegs]))
    assert stats.steer == 3
    np.testing.assert_allclose([steering_of(reply) for reply in replies], want, atol=1e-5)


def test_nan_predictions_are_counted_and_logged(jpegs, caplog) -> None:
    inputs = keras.Input(shape=(160, 320, 3))
    model = keras.Model(inputs, layers.Dense(1, name="steering")(
        layers.GlobalAveragePooling2D()(inputs)))
    model.layers[-1].set_weights([np.zeros((3, 1), np.float32), np.array([np.nan], np.float32)])
    with caplog.at_level(logging.WARNING, logger="clonedrive.udacity"):
        replies, stats = serve(NetworkPolicy(model), jpegs)
    assert [steering_of(reply) for reply in replies] == [0.0, 0.0, 0.0]
    assert stats.nan_predictions == 3
    assert "predicted NaN steering (3 frame(s) so far)" in caplog.text


def test_an_onnx_model_is_served(tmp_path: Path, jpegs) -> None:
    pytest.importorskip("onnxruntime")
    from clonedrive.model.architectures import build_model
    from clonedrive.network.onnx_runtime import export_onnx

    model = build_model("fast", seed=2)
    path = export_onnx(model, tmp_path / "model.onnx")
    replies, stats = serve(load_policy(path), jpegs)
    want = NetworkPolicy(model).predict_steering(
        np.stack([protocol.decode_image(jpeg) for jpeg in jpegs]))
    np.testing.assert_allclose([steering_of(reply) for reply in replies], want, atol=1e-4)
