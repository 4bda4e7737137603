"""Drive-server latency: one telemetry message in, one steer reply out (decode + predict + reply).

A client on 127.0.0.1 sends the simulator's telemetry frames lock-step, as the Udacity simulator
does, and times each round trip. Also times, for one frame, the parts: JPEG decode, and the
model call by ``predict_on_batch`` (what NetworkPolicy uses) against ``model(x, training=False)``.

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

from clonedrive.drivers.network import NetworkPolicy, load_model
from clonedrive.udacity import protocol
from clonedrive.udacity.server import DriveServer
from clonedrive.udacity_spec import IMAGE_SHAPE, JPEG_QUALITY, SET_SPEED_MPH

FIXTURE_IMAGES = Path(__file__).parents[1] / "tests" / "fixtures" / "udacity" / "stationary" / "IMG"


def build_default_model(architecture: str):
    try:
        from clonedrive.model.architectures import build_model
    except ModuleNotFoundError:
        from clonedrive.drivers.tiny_model import build_tiny_model

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


async def round_trips(port: int, frame: str, warmup: int, messages: int) -> list[float]:
    from websockets.asyncio.client import connect

    url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
    async with connect(url, compression=None) as ws:
        await ws.recv()  # open
        await ws.recv()  # 40
        times = []
        for index in range(warmup + messages):
            start = time.perf_counter()
            await ws.send(frame)
            reply = await ws.recv()
            elapsed = time.perf_counter() - start
            if not reply.startswith('42["steer"') or reply == protocol.SAFE_STEER_FRAME:
                raise RuntimeError(f"unexpected reply: {reply[:80]}")
            if index >= warmup:
                times.append(elapsed)
        return times


def time_parts(model, jpeg: bytes, repeats: int) -> dict[str, list[float]]:
    from clonedrive.keras_backend import import_keras

    keras = import_keras()

    batch = protocol.decode_image(jpeg)[np.newaxis].astype(np.float32)
    decode_s = time_calls(lambda: protocol.decode_image(jpeg), repeats)
    for _ in range(10):
        model.predict_on_batch(batch)
        model(batch, training=False)
    on_batch_s, call_s = [], []
    for _ in range(repeats):  # interleaved, so load from elsewhere hits both alike
        on_batch_s += time_calls(lambda: model.predict_on_batch(batch), 1)
        call_s += time_calls(lambda: keras.ops.convert_to_numpy(model(batch, training=False)), 1)
    return {"decode": decode_s, "predict_on_batch": on_batch_s, "call": call_s}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", nargs="?", default=None, help=".keras or .h5 model file")
    parser.add_argument("--messages", type=int, default=200)
    parser.add_argument("--warmup", type=int, default=20)
    parser.add_argument("--architecture", default="seed")
    args = parser.parse_args()

    from clonedrive.keras_backend import import_keras


    keras = import_keras()

    if args.model:
        model, name = load_model(args.model), args.model
    else:
        model, name = build_default_model(args.architecture)
    jpeg = sample_jpeg()

    # The parts, for one frame, timed on a worker thread as the server runs them.
    with concurrent.futures.ThreadPoolExecutor(1) as executor:
        parts = executor.submit(time_parts, model, jpeg, args.messages).result()

    # The whole round trip through a real socket.
    server = DriveServer(NetworkPolicy(model, set_speed_mph=SET_SPEED_MPH), port=0,
                         status_interval_s=0)
    port = server.start()
    try:
        frame = protocol.telemetry_frame(0.0, 0.0, 5.0, jpeg)
        trips = asyncio.run(round_trips(port, frame, args.warmup, args.messages))
    finally:
        server.stop()

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
    print(json.dumps(result))


if __name__ == "__main__":
    main()
