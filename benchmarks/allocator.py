"""Training with freed memory kept (``clonedrive.base.allocator``) against glibc's default.

Run: python benchmarks/allocator.py [--batches 60] [--rounds 3]

Each side runs in a fresh interpreter (the allocator's settings last for a process's life),
alternating, ``--rounds`` times: the ``fast`` network with a speed head and the 60-row crop, as
recipe ``best`` trains it, fitted on ``--batches`` augmented batches of 128 real Udacity frames
(tests/fixtures/udacity) through the training pipeline (image cache, flips, augmentation).
Printed per side: images/s, user and system CPU seconds, minor page faults (the best round's
images/s counts: load from other processes only ever slows a round down).
``keep_freed_speedup`` is the kept side's images/s over the default side's.

Ends with one JSON line.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

FIXTURES = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "udacity"
BATCH_SIZE = 128


def child(mode: str, batches: int) -> dict:
    """One side, in this process: train and report images/s and this process's resources."""
    import resource
    import time

    import numpy as np

    from clonedrive.base.allocator import keep_freed_memory

    kept = keep_freed_memory() if mode == "keep" else False
    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()

    from clonedrive.data.augment import AugmentConfig
    from clonedrive.data.batches import DrivingBatches, ImageCache
    from clonedrive.data.recipe import default_recipe_for, expand
    from clonedrive.model.architectures import build_model

    folders = sorted(p for p in FIXTURES.iterdir() if (p / "driving_log.csv").is_file())
    samples = expand(default_recipe_for(folders))
    cache = ImageCache(samples.unique_paths)
    cache.fill(workers=2)
    source = DrivingBatches(samples, cache, batch_size=BATCH_SIZE, shuffle=True,
                            augment=AugmentConfig(), seed=0)

    class Cycled(keras.utils.PyDataset):
        def __init__(self, count: int) -> None:
            super().__init__(workers=1)
            self.count = count

        def __len__(self) -> int:
            return self.count

        def __getitem__(self, index: int):
            images, steering = source[index % len(source)][:2]
            speed = np.full(len(steering), 0.5, np.float32)  # any label: the cost is the same
            return images, {"steering": steering, "target_speed": speed}

    model = build_model("fast", speed_head=True, crop_top_px=60)
    model.compile(optimizer=keras.optimizers.Adam(1e-3),
                  loss={"steering": "mse", "target_speed": "mse"})
    model.fit(Cycled(3), epochs=1, verbose=0)  # warm-up
    before = resource.getrusage(resource.RUSAGE_SELF)
    start = time.perf_counter()
    model.fit(Cycled(batches), epochs=1, verbose=0, shuffle=False)
    seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_SELF)
    return {"mode": mode, "kept": kept, "images_per_s": batches * BATCH_SIZE / seconds,
            "user_s": after.ru_utime - before.ru_utime,
            "system_s": after.ru_stime - before.ru_stime,
            "minor_faults": after.ru_minflt - before.ru_minflt}


def run_side(mode: str, batches: int) -> dict:
    result = subprocess.run([sys.executable, __file__, "--child", mode, "--batches",
                             str(batches)], capture_output=True, text=True, check=True)
    return json.loads(result.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, default=60, help="timed batches per side")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds")
    parser.add_argument("--child", choices=["keep", "default"], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.batches)))
        return
    rounds = {"default": [], "keep": []}
    for index in range(args.rounds):
        for mode in rounds:
            side = run_side(mode, args.batches)
            rounds[mode].append(side)
            print(f"round {index + 1} {mode:<7} {side['images_per_s']:7.1f} images/s, user "
                  f"{side['user_s']:.1f} s, system {side['system_s']:.1f} s, "
                  f"{side['minor_faults']:,} minor page faults")
    best = {mode: max(sides, key=lambda side: side["images_per_s"])
            for mode, sides in rounds.items()}
    speedup = best["keep"]["images_per_s"] / best["default"]["images_per_s"]
    print(f"keep_freed_speedup {speedup:.2f}x (best round of each)")
    print(json.dumps({
        "keep_freed_speedup": round(speedup, 3),
        "default_images_per_s": round(best["default"]["images_per_s"], 1),
        "keep_images_per_s": round(best["keep"]["images_per_s"], 1),
        "default_system_s": round(best["default"]["system_s"], 2),
        "keep_system_s": round(best["keep"]["system_s"], 2),
        "default_minor_faults": best["default"]["minor_faults"],
        "keep_minor_faults": best["keep"]["minor_faults"],
        "batch_size": BATCH_SIZE, "batches": args.batches, "rounds": args.rounds,
    }))


if __name__ == "__main__":
    main()
