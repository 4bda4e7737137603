"""A memory-mapped image cache's resident memory and read speed: frames read back with pread
(the cache's way) against reads through the mapping (its way before 2026-12-07), in one run.

A cache of N decoded frames (the fixture's JPEGs, repeated) at the demo's rows is filled, then
read in random batches as training reads it, once each way. Figures: the process's resident
memory (VmRSS) after the fill and after each way's reads, and the time per batch of each way.

Run: python benchmarks/image_cache.py [--frames 24000] [--batches 300] [--batch 256]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from clonedrive.data.batches import ImageCache

FIXTURE = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "udacity" / "stationary"
#: The rows the default recipe's network and augmentation read (crop_top_px 60).
ROWS = (54, 140)


def resident_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def timed_batches(read, count: int, batches: list[np.ndarray]) -> list[float]:
    times = []
    for indices in batches[:count]:
        start = time.perf_counter()
        read(indices)
        times.append(time.perf_counter() - start)
    return times


def main() -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=24000)
    parser.add_argument("--batches", type=int, default=300)
    parser.add_argument("--batch", type=int, default=256)
    args = parser.parse_args()
    jpegs = sorted((FIXTURE / "IMG").glob("*.jpg"))
    paths = [jpegs[index % len(jpegs)] for index in range(args.frames)]
    rng = np.random.default_rng(0)
    batches = [rng.integers(0, args.frames, size=args.batch) for _ in range(args.batches)]
    with tempfile.TemporaryDirectory(prefix="clonedrive-cache-") as folder:
        cache = ImageCache(paths, memmap_path=Path(folder) / "cache.u8", memory_limit_bytes=0,
                           rows=ROWS)
        start_mb = resident_mb()
        cache.fill(workers=2)
        filled_mb = resident_mb()
        pread = timed_batches(cache._read, args.batches, batches)
        pread_mb = resident_mb()
        mapped = timed_batches(lambda indices: cache.frames[indices], args.batches, batches)
        mapped_mb = resident_mb()
        same = all(np.array_equal(cache._read(b), cache.frames[b]) for b in batches[:5])
        result = {"frames": args.frames, "cache_mb": round(cache.nbytes / 2**20, 1),
                  "rss_start_mb": round(start_mb, 1), "rss_after_fill_mb": round(filled_mb, 1),
                  "rss_after_pread_mb": round(pread_mb, 1),
                  "rss_after_mapped_mb": round(mapped_mb, 1),
                  "pread_ms_per_batch": round(statistics.median(pread) * 1000, 2),
                  "mapped_ms_per_batch": round(statistics.median(mapped) * 1000, 2),
                  "pread_speedup": round(statistics.median(mapped) / statistics.median(pread),
                                         3),
                  "same_frames": same}
        cache.close(delete=True)
    print(f"cache {result['cache_mb']} MB; resident memory: start {result['rss_start_mb']} MB, "
          f"after the fill {result['rss_after_fill_mb']} MB, after pread reads "
          f"{result['rss_after_pread_mb']} MB, after mapped reads {result['rss_after_mapped_mb']} "
          f"MB; per batch of {args.batch}: pread {result['pread_ms_per_batch']} ms, mapped "
          f"{result['mapped_ms_per_batch']} ms ({result['pread_speedup']}x)")
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
