"""Training speed of the ``seed`` network against plain PyTorch, and input pipeline speed.

Run: python benchmarks/train.py [--batch-size 256] [--batches 8]

Measured in one process, on the same uint8 RGB batches (real Udacity frames from
tests/fixtures/udacity); Keras and PyTorch are timed in interleaved rounds and the best round
of each counts (load from other processes only ever slows a round down); the median of the
per-round ratios is printed too:

- ``seed`` trained with ``model.fit`` (Keras 3, torch backend): images/s, as built by default
  (convolutions channels-first) and with the literal channels-last layer list;
- the same network and optimiser written in plain PyTorch (crop, normalise, 4 convs, 4 dense,
  L2 1e-3 on the convs and first two dense layers, Adam 1e-4, MSE): images/s, in the faster
  of NCHW and channels-last memory layouts. Target: seed >= 0.8x of it;
- the input pipeline: JPEG decode into the cache (2 threads), and batches of cached frames
  with flips + augmentation (what every epoch after the first costs), alone and together
  (decode + augment + batch, what the first epoch costs). Target: >= 3x training throughput;
- ``model.fit`` on the real pipeline (DrivingBatches from the cache, augmented), workers 1 / 2;
- peak resident memory (``ru_maxrss``).

Ends with one JSON line.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

FIXTURES = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "udacity"


def _fixture_folders() -> list[Path]:
    folders = sorted(path for path in FIXTURES.iterdir() if (path / "driving_log.csv").is_file())
    if not folders:
        sys.exit(f"no recordings under {FIXTURES}")
    return folders


def _real_batch(cache, batch_size: int):
    import numpy as np

    rng = np.random.default_rng(0)
    indices = rng.integers(0, len(cache), size=batch_size)
    images = cache.get(indices)
    steering = rng.uniform(-0.5, 0.5, size=batch_size).astype(np.float32)
    return images, steering


class _FixedBatches:
    """A keras PyDataset of the same batch repeated: measures the model, not the pipeline."""

    def __new__(cls, images, steering, count):
        from clonedrive.base.keras_backend import import_keras

        keras = import_keras()

        class Fixed(keras.utils.PyDataset):
            def __init__(self):
                super().__init__(workers=1)

            def __len__(self):
                return count

            def __getitem__(self, index):
                return images, steering

        return Fixed()


def keras_trainer(images, steering, batches: int, data_format: str = "channels_first"):
    """A function that trains ``seed`` with model.fit on ``batches`` batches; images/s."""
    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()

    from clonedrive.model.architectures import build_model

    model = build_model("seed", data_format=data_format)
    model.compile(optimizer=keras.optimizers.Adam(1e-4), loss="mse")
    model.fit(_FixedBatches(images, steering, 2), epochs=1, verbose=0)  # warm-up
    data = _FixedBatches(images, steering, batches)

    def run() -> float:
        start = time.perf_counter()
        model.fit(data, epochs=1, verbose=0, shuffle=False)
        return batches * len(images) / (time.perf_counter() - start)

    return run


def torch_trainer(images, steering, batches: int, channels_last: bool):
    """The same network and optimiser in plain PyTorch; a function returning images/s."""
    import torch
    from torch import nn

    class Seed(nn.Module):
        def __init__(self):
            super().__init__()
            self.conv = nn.ModuleList([
                nn.Conv2d(3, 36, 5, stride=2), nn.Conv2d(36, 48, 5, stride=2),
                nn.Conv2d(48, 64, 3), nn.Conv2d(64, 64, 3),
            ])
            self.dense = nn.ModuleList([
                nn.Linear(32704, 100), nn.Linear(100, 50), nn.Linear(50, 10), nn.Linear(10, 1)
            ])

        def forward(self, frames_nhwc_uint8):
            x = frames_nhwc_uint8[:, 80:135].permute(0, 3, 1, 2).float() / 127.5 - 1.0
            if channels_last:
                x = x.contiguous(memory_format=torch.channels_last)
            for conv in self.conv:
                x = torch.relu(conv(x))
            x = torch.flatten(x, 1)
            for dense in self.dense[:-1]:
                x = torch.relu(dense(x))
            return self.dense[-1](x)

        def l2_penalty(self):
            weights = [conv.weight for conv in self.conv] + [d.weight for d in self.dense[:2]]
            return 1e-3 * sum(torch.sum(weight * weight) for weight in weights)

    net = Seed()
    if channels_last:
        net = net.to(memory_format=torch.channels_last)
    optimiser = torch.optim.Adam(net.parameters(), lr=1e-4)
    frames = torch.from_numpy(images)
    target = torch.from_numpy(steering)[:, None]

    def step():
        optimiser.zero_grad(set_to_none=True)
        loss = torch.mean((net(frames) - target) ** 2) + net.l2_penalty()
        loss.backward()
        optimiser.step()

    for _ in range(2):
        step()

    def run() -> float:
        start = time.perf_counter()
        for _ in range(batches):
            step()
        return batches * len(images) / (time.perf_counter() - start)

    return run


def pipeline_figures(samples, batch_size: int, repeats: int = 3) -> dict:
    """Decode, augment+batch (cached), and both together, images/s."""
    import numpy as np

    from clonedrive.data.augment import AugmentConfig
    from clonedrive.data.batches import DrivingBatches, ImageCache

    decode = []
    for _ in range(repeats):
        cache = ImageCache(samples.unique_paths)
        start = time.perf_counter()
        cache.fill(workers=2)
        decode.append(len(cache) / (time.perf_counter() - start))
    decode_per_s = float(np.median(decode))

    batches = DrivingBatches(samples, cache, batch_size=batch_size, shuffle=True,
                             augment=AugmentConfig(), seed=0)
    count = 0
    start = time.perf_counter()
    for _ in range(repeats):
        for index in range(len(batches)):
            count += len(batches[index][1])
        batches.on_epoch_end()
    augment_per_s = count / (time.perf_counter() - start)

    # Two threads building batches at once (what PyDataset workers=2 does).
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as pool:
        start = time.perf_counter()
        sizes = list(pool.map(lambda i: len(batches[i % len(batches)][1]),
                              range(len(batches) * repeats)))
        augment_2_per_s = sum(sizes) / (time.perf_counter() - start)

    # First epoch: every unique image decoded once, then every sample batched + augmented.
    per_sample_s = len(samples.unique_paths) / len(samples) / decode_per_s + 1 / augment_per_s
    return {
        "decode_images_per_s": decode_per_s,
        "augment_batch_images_per_s": augment_per_s,
        "augment_batch_2_threads_images_per_s": augment_2_per_s,
        "first_epoch_pipeline_images_per_s": 1.0 / per_sample_s,
        "decode_then_augment_images_per_s": 1.0 / (1 / decode_per_s + 1 / augment_per_s),
    }


def fit_pipeline_images_per_s(samples, cache, batch_size: int, batches: int, workers: int
                              ) -> float:
    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()

    from clonedrive.data.augment import AugmentConfig
    from clonedrive.data.batches import DrivingBatches
    from clonedrive.model.architectures import build_model

    subset = samples.subset(range(min(len(samples), batches * batch_size)))
    data = DrivingBatches(subset, cache, batch_size=batch_size, shuffle=True,
                          augment=AugmentConfig(), seed=0, workers=workers)
    model = build_model("seed")
    model.compile(optimizer=keras.optimizers.Adam(1e-4), loss="mse")
    model.fit(data, epochs=1, verbose=0, shuffle=False)  # warm-up
    start = time.perf_counter()
    model.fit(data, epochs=1, verbose=0, shuffle=False)
    return len(subset) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch-size", type=int, default=256)
    parser.add_argument("--batches", type=int, default=4, help="timed batches per round")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved timing rounds")
    args = parser.parse_args()

    import numpy as np
    import torch

    from clonedrive.data.batches import ImageCache
    from clonedrive.data.recipe import default_recipe_for, expand

    samples = expand(default_recipe_for(_fixture_folders()))
    cache = ImageCache(samples.unique_paths)
    cache.fill(workers=2)
    images, steering = _real_batch(cache, args.batch_size)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads; batch "
          f"{args.batch_size}, {args.batches} timed batches; {len(samples)} samples of "
          f"{len(samples.unique_paths)} real frames")

    # Interleaved rounds, best of each: other work on a shared machine only ever slows a round.
    trainers = {
        "seed": keras_trainer(images, steering, args.batches),
        "seed_channels_last": keras_trainer(images, steering, args.batches, "channels_last"),
        "torch_nchw": torch_trainer(images, steering, args.batches, channels_last=False),
        "torch_nhwc": torch_trainer(images, steering, args.batches, channels_last=True),
    }
    rounds = {name: [] for name in trainers}
    for _ in range(args.rounds):
        for name, run in trainers.items():
            rounds[name].append(run())
    for name, rates in rounds.items():
        print(f"  {name:<18} rounds: " + ", ".join(f"{rate:.1f}" for rate in rates))
    seed, seed_last, torch_nchw, torch_cl = (max(rounds[name]) for name in trainers)
    reference = max(torch_nchw, torch_cl)
    ratio = seed / reference
    # The same comparison within each round (both sides under the same load), median.
    round_ratios = [
        rates[0] / max(rates[1:])
        for rates in zip(rounds["seed"], rounds["torch_nchw"], rounds["torch_nhwc"], strict=True)
    ]
    median_ratio = float(np.median(round_ratios))
    print(f"seed (keras fit):        {seed:8.1f} images/s (convolutions channels-first, default)")
    print(f"seed, channels-last:     {seed_last:8.1f} images/s (the literal write-up layer list)")
    print(f"plain torch, NCHW:       {torch_nchw:8.1f} images/s")
    print(f"plain torch, NHWC:       {torch_cl:8.1f} images/s")
    print(f"ratio seed / best torch: {ratio:8.2f}  (target >= 0.8: "
          f"{'met' if ratio >= 0.8 else 'NOT met'}); per round: "
          + ", ".join(f"{value:.2f}" for value in round_ratios)
          + f" (median {median_ratio:.2f})")

    pipeline = pipeline_figures(samples, args.batch_size)
    cached_ratio = pipeline["augment_batch_images_per_s"] / seed
    cold_ratio = pipeline["first_epoch_pipeline_images_per_s"] / seed
    print(f"decode (2 threads):      {pipeline['decode_images_per_s']:8.1f} images/s")
    print(f"augment + batch, cached: {pipeline['augment_batch_images_per_s']:8.1f} images/s "
          f"(1 thread), {pipeline['augment_batch_2_threads_images_per_s']:.1f} (2 threads)")
    print(f"first epoch (decode each image once + augment + batch): "
          f"{pipeline['first_epoch_pipeline_images_per_s']:.1f} images/s")
    print(f"pipeline / training:     {cached_ratio:8.2f} cached, {cold_ratio:.2f} first epoch "
          f"(target >= 3: {'met' if min(cached_ratio, cold_ratio) >= 3 else 'NOT met'})")

    fit_rates = {
        workers: fit_pipeline_images_per_s(samples, cache, args.batch_size, 4, workers)
        for workers in (1, 2)
    }
    for workers, rate in fit_rates.items():
        print(f"seed fit on the real pipeline, workers={workers}: {rate:8.1f} images/s")
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB
    print(f"peak memory (ru_maxrss): {peak_mb:8.0f} MB")

    print(json.dumps({
        "seed_images_per_s": round(seed, 1),
        "torch_reference_images_per_s": round(reference, 1),
        "ratio": round(ratio, 3),
        "pipeline_ratio": round(cached_ratio, 2),
        "ratio_median_of_rounds": round(median_ratio, 3),
        "pipeline_first_epoch_ratio": round(cold_ratio, 2),
        "seed_channels_last_images_per_s": round(seed_last, 1),
        "torch_nchw_images_per_s": round(torch_nchw, 1),
        "torch_channels_last_images_per_s": round(torch_cl, 1),
        **{key: round(value, 1) for key, value in pipeline.items()},
        "fit_real_pipeline_images_per_s": {str(k): round(v, 1) for k, v in fit_rates.items()},
        "peak_rss_mb": round(peak_mb),
        "rounds": {name: [round(rate, 1) for rate in rates] for name, rates in rounds.items()},
        "batch_size": args.batch_size,
        "torch_threads": torch.get_num_threads(),
        "numpy": np.__version__,
    }))


if __name__ == "__main__":
    main()
