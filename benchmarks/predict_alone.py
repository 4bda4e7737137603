"""What predicting each frame alone costs against one batched call, per architecture.

The network policy puts every frame through the network alone (``NetworkPolicy.predict``), so
that a car's steering does not depend on the cars driven beside it. This measures the time of
that against the batched call it replaced (``NetworkPolicy._predict`` on the whole batch, the
same preprocessing, mirroring and clipping), on the same real frames, in the same run:

- ``alone_over_batched_<model>_<n>``: seconds for N frames one at a time / as one batch (median
  of 5 alternating pairs), for N = 7 (one half of the demo's lock-step group of 14 cars, as
  evaluate's overlap predicts it) and N = 14, and for N = 256 (an offline pass, as ``replay``
  and ``crosscheck`` make).
- Models: ``fast`` as the ``best`` recipe drives it (speed head, 60-row crop, mirror averaging),
  and the untrained ``seed`` (the write-up's network) and ``pilotnet`` without mirroring. The
  weights do not change the cost.

One PyTorch thread, as evaluate's and bench's worker processes run.

Run: python benchmarks/predict_alone.py
"""

from __future__ import annotations

import json
import statistics
import time
from pathlib import Path

import numpy as np

FIXTURES = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "udacity"
SIZES = (7, 14, 256)
PAIRS = 5


def real_frames(count: int) -> np.ndarray:
    from PIL import Image

    paths = sorted(FIXTURES.glob("*/IMG/center_*.jpg"))
    frames = [np.asarray(Image.open(path).convert("RGB")) for path in paths]
    return np.stack([frames[index % len(frames)] for index in range(count)])


def policies() -> dict:
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.model.architectures import build_model

    return {
        "fast": NetworkPolicy(build_model("fast", seed=1, speed_head=True, crop_top_px=60),
                              mirror_average=True),
        "seed": NetworkPolicy(build_model("seed", seed=1)),
        "pilotnet": NetworkPolicy(build_model("pilotnet", seed=1)),
    }


def seconds(call) -> float:
    start = time.perf_counter()
    call()
    return time.perf_counter() - start


def ratio(policy, frames: np.ndarray) -> tuple[float, float, float]:
    """(median alone / batched, median alone [s], median batched [s])."""
    alone = lambda: policy.predict(frames)  # noqa: E731
    batched = lambda: policy._predict(frames)  # noqa: E731
    alone(), batched()  # traces and warm-up for both shapes
    pairs = [(seconds(alone), seconds(batched)) for _ in range(PAIRS)]
    return (statistics.median(a / b for a, b in pairs),
            statistics.median(a for a, _ in pairs), statistics.median(b for _, b in pairs))


def main() -> None:
    import torch

    torch.set_num_threads(1)
    frames = real_frames(max(SIZES))
    figures = {}
    for name, policy in policies().items():
        for size in SIZES:
            value, alone, batched = ratio(policy, frames[:size])
            print(f"{name:9s} {size:4d} frames: alone {alone * 1000:8.1f} ms, "
                  f"batched {batched * 1000:8.1f} ms, ratio {value:.2f}")
            figures[f"alone_over_batched_{name}_{size}"] = round(value, 3)
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
