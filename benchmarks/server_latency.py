"""Drive-server latency: one telemetry message in, one steer reply out (decode + predict + reply).

A client on 127.0.0.1 sends the simulator's telemetry frames lock-step, as the Udacity simulator
does, and times each round trip. Also times, for one frame, the parts: JPEG decode, and the
model call by ``predict_on_batch`` (what NetworkPolicy uses) against ``model(x, training=False)``.

Keras and ONNX Runtime in the same run: the model is also exported to ONNX (in memory) and
served by a second drive server; the client alternates one message to each, so load from
elsewhere on the machine hits both alike. ``onnx_latency_ratio`` = the ONNX Runtime server's
median round trip / the Keras server's (target <= 0.5); ``onnx_predict_ratio`` the same for the
model call alone. Without the onnx extra the ONNX figures are null.

Run: python benchmarks/server_latency.py [MODEL.keras] [--messages 200] [--architecture seed]
Without a model file it builds ``build_model(architecture)`` from clonedrive.model.architectures,
or the tiny test model if that module is missing. The simulator sends ~15 messages/s, so a
median round trip well under 66 ms keeps up.
"""

from __future__ import annotations

import argparse
import asyncio
import concurrent.futures
import json
import statistics
import time
from pathlib import Path

import numpy as np

from clonedrive.base.udacity_spec import IMAGE_SHAPE, JPEG_QUALITY, SET_SPEED_MPH
from clonedrive.drivers.policy import NetworkPolicy
from clonedrive.network.model_file import load_model
from clonedrive.udacity import protocol
from clonedrive.udacity.server import DriveServer

FIXTURE_IMAGES = Path(__file__).parents[1] / "tests" / "fixtures" / "udacity" / "stationary" / "IMG"


def build_default_model(architecture: str):
    try:
        from clonedrive.model.architectures import build_model
    except ModuleNotFoundError:
        from clonedrive.network.tiny_model import build_tiny_model

        print("clonedrive.model.architectures not found: using the tiny test model")
        return build_tiny_model(), "tiny"
    return build_model(architecture), architecture


def sample_jpeg() -> bytes:
    files = sorted(FIXTURE_IMAGES.glob("center_*.jpg"))
    if files:
        return files[0].read_bytes()
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, size=IMAGE_SHAPE, dtype=np.uint8)
    return protocol.encode_image(image, quality=JPEG_QUALITY)


def percentile_ms(values_s: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values_s), q) * 1e3)


def time_calls(function, repeats: int) -> list[float]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return times


async def round_trips(ports: list[int], frame: str, warmup: int,
                      messages: int) -> list[list[float]]:
    """Round-trip times per server; one message to each server in turn (interleaved)."""
    from contextlib import AsyncExitStack

    from websockets.asyncio.client import connect

    async with AsyncExitStack() as stack:
        sockets = []
        for port in ports:
            url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
            ws = await stack.enter_async_context(connect(url, compression=None))
            await ws.recv()  # open
            await ws.recv()  # 40
            sockets.append(ws)
        times: list[list[float]] = [[] for _ in ports]
        for index in range(warmup + messages):
            for server, ws in enumerate(sockets):
                start = time.perf_counter()
                await ws.send(frame)
                reply = await ws.recv()
                elapsed = time.perf_counter() - start
                if not reply.startswith('42["steer"') or reply == protocol.SAFE_STEER_FRAME:
                    raise RuntimeError(f"unexpected reply: {reply[:80]}")
                if index >= warmup:
                    times[server].append(elapsed)
        return times


def time_parts(model, jpeg: bytes, repeats: int, onnx_model=None) -> dict[str, list[float]]:
    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()

    batch = protocol.decode_image(jpeg)[np.newaxis].astype(np.float32)
    decode_s = time_calls(lambda: protocol.decode_image(jpeg), repeats)
    for _ in range(10):
        model.predict_on_batch(batch)
        model(batch, training=False)
        if onnx_model is not None:
            onnx_model.predict_on_batch(batch)
    on_batch_s, call_s, onnx_s = [], [], []
    for _ in range(repeats):  # interleaved, so load from elsewhere hits all alike
        on_batch_s += time_calls(lambda: model.predict_on_batch(batch), 1)
        call_s += time_calls(lambda: keras.ops.convert_to_numpy(model(batch, training=False)), 1)
        if onnx_model is not None:
            onnx_s += time_calls(lambda: onnx_model.predict_on_batch(batch), 1)
    return {"decode": decode_s, "predict_on_batch": on_batch_s, "call": call_s,
            "onnx_predict": onnx_s}


def onnx_twin(model):
    """The model converted to ONNX and run by ONNX Runtime, or None without the onnx extra."""
    try:
        from clonedrive.network.onnx_runtime import OnnxModel, onnx_bytes

        return OnnxModel(onnx_bytes(model), source="benchmark model (ONNX)")
    except ValueError as error:  # the extra is not installed
        print(f"no ONNX figures: {error}")
        return None


def median_ms(values_s: list[float]) -> float | None:
    return round(statistics.median(values_s) * 1e3, 3) if values_s else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", nargs="?", default=None, help=".keras or .h5 model file")
    parser.add_argument("--messages", type=int, default=200)
    parser.add_argument("--warmup", type=int, default=20)
    parser.add_argument("--architecture", default="seed")
    args = parser.parse_args()

    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()

    if args.model:
        model, name = load_model(args.model), args.model
    else:
        model, name = build_default_model(args.architecture)
    jpeg = sample_jpeg()
    onnx_model = onnx_twin(model)

    # The parts, for one frame, timed on a worker thread as the server runs them.
    with concurrent.futures.ThreadPoolExecutor(1) as executor:
        parts = executor.submit(time_parts, model, jpeg, args.messages, onnx_model).result()

    # The whole round trip through a real socket: Keras, and ONNX Runtime, interleaved.
    servers = [DriveServer(NetworkPolicy(served, set_speed_mph=SET_SPEED_MPH), port=0,
                           status_interval_s=0)
               for served in ([model] if onnx_model is None else [model, onnx_model])]
    ports = [server.start() for server in servers]
    try:
        frame = protocol.telemetry_frame(0.0, 0.0, 5.0, jpeg)
        all_trips = asyncio.run(round_trips(ports, frame, args.warmup, args.messages))
    finally:
        for server in servers:
            server.stop()
    trips = all_trips[0]
    onnx_trips = all_trips[1] if onnx_model is not None else []
    onnx_trip_ms = median_ms(onnx_trips)
    onnx_predict_ms = median_ms(parts["onnx_predict"])
    keras_predict_ms = median_ms(parts["predict_on_batch"])

    result = {
        "model": name,
        "backend": keras.backend.backend(),
        "messages": len(trips),
        "frame_bytes": len(frame),
        "round_trip_median_ms": round(statistics.median(trips) * 1e3, 3),
        "round_trip_p99_ms": round(percentile_ms(trips, 99), 3),
        "messages_per_s": round(len(trips) / sum(trips), 1),
        "decode_median_ms": round(statistics.median(parts["decode"]) * 1e3, 3),
        "predict_on_batch_median_ms": round(statistics.median(parts["predict_on_batch"]) * 1e3, 3),
        "model_call_median_ms": round(statistics.median(parts["call"]) * 1e3, 3),
        "onnx_round_trip_median_ms": onnx_trip_ms,
        "onnx_round_trip_p99_ms": round(percentile_ms(onnx_trips, 99), 3) if onnx_trips else None,
        "onnx_predict_median_ms": onnx_predict_ms,
        "onnx_latency_ratio": (round(onnx_trip_ms / median_ms(trips), 3)
                               if onnx_trip_ms is not None else None),
        "onnx_predict_ratio": (round(onnx_predict_ms / keras_predict_ms, 3)
                               if onnx_predict_ms is not None else None),
    }
    print(
        f"model {name} on {result['backend']}, {len(trips)} telemetry messages "
        f"of {len(frame)} bytes, lock-step over 127.0.0.1"
    )
    print(
        f"  round trip  median {result['round_trip_median_ms']:7.2f} ms   "
        f"p99 {result['round_trip_p99_ms']:7.2f} ms   ({result['messages_per_s']} msg/s; "
        "the simulator needs 15)"
    )
    print(f"  JPEG decode median {result['decode_median_ms']:7.2f} ms")
    print(
        f"  predict_on_batch   {result['predict_on_batch_median_ms']:7.2f} ms   "
        f"model(x, training=False) {result['model_call_median_ms']:7.2f} ms (one frame)"
    )
    if onnx_model is not None:
        print(
            f"  ONNX Runtime: round trip median {onnx_trip_ms:7.2f} ms   p99 "
            f"{result['onnx_round_trip_p99_ms']:7.2f} ms; model call {onnx_predict_ms:7.2f} ms"
        )
        print(
            f"  onnx_latency_ratio {result['onnx_latency_ratio']:.3f} (ONNX Runtime / Keras round "
            f"trip; target <= 0.5), onnx_predict_ratio {result['onnx_predict_ratio']:.3f}"
        )
    print(json.dumps(result))


if __name__ == "__main__":
    main()
