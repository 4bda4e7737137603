"""Training and inference speed of the ``fast`` network against its previous layer order.

Run: python benchmarks/fast_layout.py [--batch-size 256] [--rounds 5] [--steps 8]

``fast`` (``best``'s network: speed head, 60-row crop) as the package builds it now, with the
channels moved first on the uint8 crop and the pooling in the convolutions' layout, against the
same network in the layer order it had up to 2026-12-06 (Rescaling and a channels-last pooling
ahead of the Permute), built here as the reference in front of the same layers and weights
from the first convolution on. Both train with ``train_on_batch`` (Adam, MSE on both heads)
and predict on the same random uint8 frames, in interleaved rounds; each one's best round
counts (load from other processes only ever slows a round down), and the median of the
per-round ratios is printed too. The largest difference between the two networks' predictions
shows they compute the same function.

Ends with one JSON line: ``train_speedup`` and ``predict_speedup`` (reference time over the
package's, > 1 is faster), their medians, the step times in ms and ``max_abs_diff``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time


def _in_previous_order(keras, model):
    """``model``'s own layers from the first convolution on (the same weights), after the
    preprocessing in ``fast``'s previous order: scaled, pooled channels-last, then Permute."""
    layers = keras.layers
    inputs = keras.Input(shape=(160, 320, 3), dtype="uint8", name="image_rgb")
    x = layers.Cropping2D(model.get_layer("crop").cropping)(inputs)
    x = layers.Rescaling(1.0 / 127.5, offset=-1.0)(x)
    x = layers.AveragePooling2D(pool_size=(2, 2))(x)
    x = layers.Permute((3, 1, 2))(x)
    for name in ("conv1", "conv2", "conv3", "flatten", "dense1"):
        x = model.get_layer(name)(x)
    return keras.Model(inputs, [model.get_layer(name)(x) for name in ("steering", "target_speed")],
                       name="fast_previous")


def _seconds_per_call(function, steps: int) -> float:
    function()
    start = time.perf_counter()
    for _ in range(steps):
        function()
    return (time.perf_counter() - start) / steps


def _round(models, frames, labels, steps: int) -> dict[str, tuple[float, float]]:
    return {name: (_seconds_per_call(lambda m=model: m.train_on_batch(frames, labels), steps),
                   _seconds_per_call(lambda m=model: m.predict_on_batch(frames), steps))
            for name, model in models.items()}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch-size", type=int, default=256,
                        help="frames per step (256: a consistency step of batch 128)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=8, help="steps timed per round")
    args = parser.parse_args(argv)

    import numpy as np

    from clonedrive.base.keras_backend import import_keras
    from clonedrive.model.architectures import build_model

    keras = import_keras()
    package = build_model("fast", seed=0, speed_head=True, crop_top_px=60)
    previous = _in_previous_order(keras, package)
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, (args.batch_size, 160, 320, 3), dtype=np.uint8)
    difference = max(float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) for a, b in zip(
        package.predict_on_batch(frames), previous.predict_on_batch(frames), strict=True))
    labels = [rng.uniform(-0.5, 0.5, (args.batch_size, 1)).astype(np.float32) for _ in range(2)]
    models = {"package": package, "previous": previous}
    for model in models.values():
        model.compile(optimizer=keras.optimizers.Adam(1e-4), loss=["mse", "mse"])
    rounds = [_round(models, frames, labels, args.steps) for _ in range(args.rounds)]
    result = _summary(rounds, difference, args.batch_size)
    print(json.dumps(result))
    return result


def _summary(rounds, difference: float, batch_size: int) -> dict:
    figures = {"batch_size": batch_size, "rounds": len(rounds), "max_abs_diff": difference}
    for slot, kind in enumerate(("train", "predict")):
        best = {name: min(entry[name][slot] for entry in rounds) for name in rounds[0]}
        ratios = [entry["previous"][slot] / entry["package"][slot] for entry in rounds]
        figures[f"{kind}_ms"] = round(best["package"] * 1000, 1)
        figures[f"{kind}_ms_previous"] = round(best["previous"] * 1000, 1)
        figures[f"{kind}_speedup"] = round(best["previous"] / best["package"], 3)
        figures[f"{kind}_speedup_median"] = round(statistics.median(ratios), 3)
        print(f"{kind}: {figures[f'{kind}_ms']} ms per {batch_size} frames, previous layer "
              f"order {figures[f'{kind}_ms_previous']} ms: {figures[f'{kind}_speedup']}x "
              f"(median of rounds {figures[f'{kind}_speedup_median']}x)")
    print(f"largest difference between the two networks' predictions: {difference:.2e}")
    return figures


if __name__ == "__main__":
    main()
