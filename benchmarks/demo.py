"""Demo timings: `clonedrive demo --quick` (target <= 3 min) and, with --full, the default demo
(target <= 15 min on this 2-core machine), from an empty folder each, with stage timings and the
default demo's driving results.

Run: python benchmarks/demo.py [--full] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path


def timed_demo(out: Path, **options) -> dict:
    from clonedrive.pipelines.demo import DemoConfig, run_demo

    start = time.perf_counter()
    summary = run_demo(DemoConfig(**options), out, progress=False)
    summary["wall_seconds"] = round(time.perf_counter() - start, 1)
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="also run the default demo (~15 min)")
    parser.add_argument("--keep", default=None, help="keep the run folders under this folder")
    args = parser.parse_args()
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="clonedrive-demo-"))
    result: dict = {}
    try:
        quick = timed_demo(root / "quick", quick=True)
        result["quick_seconds"] = quick["wall_seconds"]
        print(f"demo --quick: {quick['wall_seconds']:.0f} s (target <= 180 s); stages "
              + ", ".join(f"{k} {v['seconds']:.0f} s" for k, v in quick["stages"].items()))
        if args.full:
            full = timed_demo(root / "full")
            result["default_seconds"] = full["wall_seconds"]
            result["default_stages_s"] = {k: v["seconds"] for k, v in full["stages"].items()}
            totals = full["stages"]["evaluate"]["totals"]
            result["default_totals"] = totals
            runs = json.loads((root / "full" / "eval" / "eval.json").read_text())["runs"]
            result["default_runs"] = [
                {key: run[key] for key in ("track", "speed_mph", "laps_completed",
                                           "laps_target", "interventions")} for run in runs]
            print(f"demo (default): {full['wall_seconds']:.0f} s (target <= 900 s); stages "
                  + ", ".join(f"{k} {v:.0f} s" for k, v in result["default_stages_s"].items()))
            for run in result["default_runs"]:
                print(f"  {run['track']:<10} {run['speed_mph']:>4g} mph: "
                      f"{run['laps_completed']}/{run['laps_target']} laps, "
                      f"{run['interventions']} interventions")
    finally:
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
