"""`clonedrive bench` with the crop against `--full-frame`: wall time and results, one run.

``bench_speedup``: the wall time of `clonedrive bench MODEL --split new-tracks-hard` (suite v2,
all its episodes, the expert's reference laps included, workers: one per core) with
``--full-frame`` / without (only the rows the model's crop keeps rendered), measured one after
the other in this run. ``identical``: whether every episode's laps, interventions and clean flag
are the same both ways; the largest difference in mean |CTE| is reported beside it (the cropped
frames differ from the full ones by texture sampling noise, see ``benchmarks/crop.py``).

Run: python benchmarks/bench_crop.py MODEL.keras [--split new-tracks-hard]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time


def run_bench(model: str, split: str, full_frame: bool) -> tuple[float, dict]:
    from clonedrive.bench.run import BenchConfig, bench

    config = BenchConfig(models=(f"model={model}",), splits=(split,), full_frame=full_frame,
                         renderer="software")
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        report = bench(config, out, progress=False)
        return time.perf_counter() - start, report


def outcomes(report: dict) -> dict:
    model = next(iter(report["models"].values()))
    return {run["key"]: run for run in model["runs"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model")
    parser.add_argument("--split", default="new-tracks-hard")
    args = parser.parse_args()
    load = os.getloadavg()[0]
    print(f"load average before: {load:.2f} on {os.cpu_count()} CPUs")
    cropped_s, cropped = run_bench(args.model, args.split, full_frame=False)
    full_s, full = run_bench(args.model, args.split, full_frame=True)
    a, b = outcomes(cropped), outcomes(full)
    keys = ("laps_completed", "interventions", "clean")
    same = sorted(a) == sorted(b) and all(
        all(a[k][key] == b[k][key] for key in keys) for k in a)
    cte = max(abs(a[k]["mean_abs_cte_m"] - b[k]["mean_abs_cte_m"]) for k in a)
    for k in sorted(a):
        print(f"  {k}: cropped {[a[k][key] for key in keys]} mean|CTE| "
              f"{a[k]['mean_abs_cte_m']:.3f}; full frame {[b[k][key] for key in keys]} "
              f"{b[k]['mean_abs_cte_m']:.3f}")
    speedup = full_s / cropped_s
    print(f"bench {args.split}: cropped {cropped_s:.1f} s, full frame {full_s:.1f} s -> "
          f"bench_speedup {speedup:.2f}; laps, interventions and clean flags "
          f"{'identical' if same else 'NOT identical'}; largest mean |CTE| difference "
          f"{cte:.3f} m")
    print(json.dumps({"bench_speedup": round(speedup, 3), "identical": same,
                      "cropped_s": round(cropped_s, 1), "full_frame_s": round(full_s, 1),
                      "max_mean_abs_cte_difference_m": round(cte, 4),
                      "episodes": len(a), "split": args.split,
                      "rendering": cropped["rendering"], "load_average": round(load, 2)}))


if __name__ == "__main__":
    main()
