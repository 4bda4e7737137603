"""Bench throughput: episodes per second of `clonedrive bench`'s worker pool, 1 and N workers.

The same fixed list of episodes (train-tracks and new-tracks-hard of suite v2, each capped at
`--seconds` of simulated time, full scenery, an untrained `fast` network: the weights do not
change the cost) is driven by the pool with 1 worker and with N workers (default: the CPU
cores). Each batch runs in a fresh process, so the figures include process start and model
load, as `clonedrive bench` pays them. Target: parallel_speedup >= 1.8 on 2 cores. Also checks
that both runs gave identical results.

Run: python benchmarks/bench.py [--workers N] [--seconds S] [--episodes K]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path


def main() -> int:
    from clonedrive.base.workers import default_workers, run_tasks
    from clonedrive.bench import DEFAULT_SUITE
    from clonedrive.bench.driving import drive_batch
    from clonedrive.bench.run import BenchConfig, plan_tasks
    from clonedrive.bench.suite import load_suite
    from clonedrive.model.architectures import build_model

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=default_workers())
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--episodes", type=int, default=8, help="episodes (batches of 2)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        model = Path(folder) / "fast.keras"
        build_model("fast").save(model)
        config = BenchConfig(models=(str(model),), splits=("train-tracks", "new-tracks-hard"),
                             batch=2, max_seconds=args.seconds)
        tasks, _ = plan_tasks(load_suite(DEFAULT_SUITE), config)
        tasks = [t for t in tasks if t.kind == "model"][: max(1, args.episodes // 2)]
        episodes = sum(len(t["episodes"]) for t in tasks)
        figures, results = {}, {}
        for workers in (1, args.workers):
            start = time.perf_counter()
            results[workers] = run_tasks(drive_batch, tasks, workers=workers)
            figures[workers] = episodes / (time.perf_counter() - start)
            print(f"{workers} worker(s): {episodes} episodes of {args.seconds:g} s in "
                  f"{episodes / figures[workers]:.1f} s: {figures[workers]:.3f} episodes/s")
    speedup = figures[args.workers] / figures[1]
    identical = json.dumps(results[1], sort_keys=True) == json.dumps(results[args.workers],
                                                                   sort_keys=True)
    print(f"parallel_speedup {speedup:.2f} with {args.workers} workers (target >= 1.8 on 2 "
          f"cores); results identical: {identical}")
    print(json.dumps({"episodes": episodes, "episode_seconds": args.seconds,
                      "workers": args.workers, "episodes_per_s_1": round(figures[1], 4),
                      "episodes_per_s_n": round(figures[args.workers], 4),
                      "parallel_speedup": round(speedup, 3), "identical": identical}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
