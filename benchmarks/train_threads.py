"""Who shares the cores while the default recipe trains: OpenCV's thread pool against PyTorch's.

Run: python benchmarks/train_threads.py [--batches 24] [--rounds 3] [--looks 0.3]

The default recipe's network (``fast``, 60-row crop) is trained with ``model.fit`` on the real
input pipeline (``DrivingBatches`` over cached real frames from tests/fixtures/udacity,
augmented, only the rows the crop keeps), the same batches each time, in three set-ups:

- ``today``: OpenCV's own thread pool (one thread per core) and one batch at a time;
- ``cv2_1``: OpenCV on one thread (``cv2.setNumThreads(1)``), one batch at a time;
- ``cv2_1_workers_2``: OpenCV on one thread, two PyDataset worker threads (the next batch is
  made while the network trains on this one).

Each set-up trains a fresh network from the same initial weights on the same batches. OpenCV's
thread count cannot change a pixel, so ``cv2_1``'s final weights must equal today's to the bit
(the benchmark exits 1 if not); whether ``cv2_1_workers_2``'s do is printed as a finding (on
2026-12-07 they did not: Keras's threaded batch queue trains another model).
Rounds are interleaved and the best of each set-up counts (other work only slows a round);
the ratios are against ``today`` in the same run. ``--looks P`` restyles that share of frames
(``train --augment-looks``), as a recipe with it would. Ends with one JSON line.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

FIXTURES = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "udacity"
SETUPS = {"today": (None, 1), "cv2_1": (1, 1), "cv2_1_workers_2": (1, 2)}


def _samples_and_cache():
    from clonedrive.data.batches import ImageCache
    from clonedrive.data.recipe import default_recipe_for, expand

    folders = sorted(path for path in FIXTURES.iterdir() if (path / "driving_log.csv").is_file())
    if not folders:
        sys.exit(f"no recordings under {FIXTURES}")
    samples = expand(default_recipe_for(folders))
    cache = ImageCache(samples.unique_paths)
    cache.fill(workers=2)
    return samples, cache


def _train(samples, cache, *, batches: int, batch_size: int, looks: float, cv2_threads,
           workers: int):
    """(seconds for one epoch of ``batches`` batches after a warm-up epoch, final weights)."""
    import cv2
    import numpy as np

    from clonedrive.base.keras_backend import import_keras
    from clonedrive.data.augment import AugmentConfig
    from clonedrive.data.batches import DrivingBatches
    from clonedrive.model.architectures import build_model
    from clonedrive.network.crop import visible_rows

    keras = import_keras()
    default_threads = cv2.getNumThreads()
    cv2.setNumThreads(default_threads if cv2_threads is None else cv2_threads)
    try:
        keras.utils.set_random_seed(0)
        model = build_model("fast", seed=0, crop_top_px=60)
        model.compile(optimizer=keras.optimizers.Adam(1e-3), loss="mse")
        subset = samples.subset(range(min(len(samples), batches * batch_size)))
        data = DrivingBatches(subset, cache, batch_size=batch_size, shuffle=True,
                              augment=AugmentConfig(looks_probability=looks), seed=0,
                              workers=workers, rows=visible_rows(model))
        model.fit(data, epochs=1, verbose=0, shuffle=False)  # warm-up: the same first epoch
        start = time.perf_counter()
        model.fit(data, epochs=1, verbose=0, shuffle=False)
        seconds = time.perf_counter() - start
        return seconds, [np.asarray(weight) for weight in model.get_weights()]
    finally:
        cv2.setNumThreads(default_threads)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, default=24, help="timed batches per round")
    parser.add_argument("--batch-size", type=int, default=128)
    parser.add_argument("--rounds", type=int, default=3, help="interleaved timing rounds")
    parser.add_argument("--looks", type=float, default=0.0, help="share of frames restyled")
    args = parser.parse_args()

    import cv2
    import numpy as np
    import torch

    samples, cache = _samples_and_cache()
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads; OpenCV "
          f"{cv2.__version__}, {cv2.getNumThreads()} threads by default; {args.batches} "
          f"batches of {args.batch_size} from {len(samples.unique_paths)} real frames; "
          f"looks {args.looks:g}")
    seconds = {name: [] for name in SETUPS}
    weights = {}
    for _ in range(args.rounds):
        for name, (threads, workers) in SETUPS.items():
            took, weights[name] = _train(samples, cache, batches=args.batches,
                                         batch_size=args.batch_size, looks=args.looks,
                                         cv2_threads=threads, workers=workers)
            seconds[name].append(took)
    best = {name: min(values) for name, values in seconds.items()}
    images = args.batches * args.batch_size
    for name, values in seconds.items():
        print(f"  {name:<16} {images / best[name]:8.1f} images/s (rounds: "
              + ", ".join(f"{value:.2f} s" for value in values) + ")")
    speedups = {name: best["today"] / best[name] for name in SETUPS}
    for name, value in speedups.items():
        print(f"speed-up against today, {name:<16} {value:.2f}x")
    same = {name: all(np.array_equal(a, b) for a, b in zip(weights["today"], weights[name],
                                                             strict=True))
            for name in SETUPS}
    print("final weights equal to today's: " + ", ".join(f"{k} {v}" for k, v in same.items()))
    print(json.dumps({
        "looks": args.looks,
        "images_per_s": {name: round(images / value, 1) for name, value in best.items()},
        "speedup": {name: round(value, 3) for name, value in speedups.items()},
        "same_weights": same,
    }))
    if not same["cv2_1"]:
        sys.exit(1)


if __name__ == "__main__":
    main()
