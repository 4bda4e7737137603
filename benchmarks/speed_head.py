"""Speed head at a 30 mph cap, no curve rule: clean laps, lap time and smoothness vs the expert.

Issue 12's targets, measured with `clonedrive bench`: a model with a speed head (`train
--speed-head`), driving with no `slow_in_curves` at a 30 mph cap, is clean on the mountain and on
every benchmark track (suite v2's train-tracks and new-tracks easy/medium/hard, clear look, one
lap from a standing start), with a lap time <= 1.05x the expert's and a smoothness ratio (mean
|steering change| per second over the expert's) <= 1.2. With `--baseline MODEL` a one-output
model is driven the same way with the hand-made curve rule (`slow_in_curves`), for comparison.

Run: python benchmarks/speed_head.py MODEL [--baseline MODEL] [--steering-filter S]
         [--steering-hold H] [--mirror-average] [--workers N] [--out DIR] [--max-seconds S]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

#: The default suite's splits that name the benchmark's tracks, driven at the cap only.
SPLITS = ("train-tracks", "new-tracks-easy", "new-tracks-medium", "new-tracks-hard")
CAP_MPH = 30.0


def suite_at_cap(folder: Path) -> Path:
    """The default suite's track splits at the 30 mph cap only, clear look, as a suite file."""
    from clonedrive.bench import DEFAULT_SUITE
    from clonedrive.bench.suite import load_suite

    base = load_suite(DEFAULT_SUITE).to_dict()
    lines = ['id = "v2-tracks-30mph"', 'description = "suite v2 tracks at the 30 mph cap"',
             "laps = 1", ""]
    for split in base["splits"]:
        if split["name"] not in SPLITS:
            continue
        tracks = ", ".join(f'"{name}"' for name in split["tracks"])
        lines += ["[[split]]", f'name = "{split["name"]}"', f"tracks = [{tracks}]",
                  f"speeds_mph = [{CAP_MPH}]", 'conditions = ["clear"]',
                  f"seed = {split['seed']}", ""]
    lines += ["[conditions.clear]", "held_out = false",
              'description = "the theme\'s own look"', ""]
    path = folder / "suite.toml"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def run_bench(model: str, suite: Path, out: Path, *, slow_in_curves: bool, workers: int | None,
              steering_filter_s: float, steering_hold: float, mirror_average: bool,
              max_seconds: float | None) -> dict:
    from clonedrive.bench.run import BenchConfig, bench

    config = BenchConfig(models=(f"model={model}",), suite=str(suite), workers=workers,
                         slow_in_curves=slow_in_curves, steering_filter_s=steering_filter_s,
                         steering_hold=steering_hold, mirror_average=mirror_average,
                         max_seconds=max_seconds)
    report = bench(config, out, progress=True)
    model = next(iter(report["models"].values()))
    return {**model, "reference": report["reference"]}


#: The smoothness figures besides the steering rate, each as mean run / expert on the same track.
OTHER_SMOOTHNESS = ("steering_jerk_per_s2", "lateral_accel_rms_mps2", "lateral_jerk_mps3")


def smoothness_ratios(runs: list[dict], reference: dict) -> dict:
    """Mean over the runs of each of :data:`OTHER_SMOOTHNESS` over the expert's reference run
    on the same track and speed (runs without a reference, or a zero one, are left out)."""
    ratios = {}
    for figure in OTHER_SMOOTHNESS:
        values = []
        for run in runs:
            expert = reference.get(f"{run['track']}@{run['speed_mph']:g}", {}).get(figure)
            if expert and run.get(figure) is not None:
                values.append(run[figure] / expert)
        ratios[figure] = round(sum(values) / len(values), 4) if values else None
    return ratios


def summary(model: dict) -> dict:
    runs = model["runs"]
    mountain = [r for r in runs if r["track"] == "mountain"]
    timed = [r for r in runs if r["scores"]["lap_time_ratio"]]
    ratios = [r["scores"]["lap_time_ratio"] for r in timed]
    slowest = max(timed, key=lambda r: r["scores"]["lap_time_ratio"]) if timed else None
    smooth = [r["scores"]["smoothness_ratio"] for r in runs if r["scores"]["smoothness_ratio"]]
    return {
        "runs": len(runs),
        "clean_runs": sum(1 for r in runs if r["clean"]),
        "mountain_clean": bool(mountain and all(r["clean"] for r in mountain)),
        "max_lap_time_ratio": round(max(ratios), 4) if ratios else None,
        "mean_lap_time_ratio": round(sum(ratios) / len(ratios), 4) if ratios else None,
        "mean_smoothness_ratio": round(sum(smooth) / len(smooth), 4) if smooth else None,
        "mean_smoothness_ratios_other": smoothness_ratios(runs, model.get("reference", {})),
        "slowest": (f"{slowest['track']} ({slowest['scores']['lap_time_ratio']:.3f})"
                    if slowest else None),
        "splits": {name: {key: figures.get(key) for key in
                          ("success_pct", "interventions_per_km", "lap_time_ratio",
                           "smoothness_ratio")}
                   for name, figures in model["splits"].items()},
        "failed": [f"{r['track']} ({r['interventions']} interventions)" for r in runs
                   if not r["clean"]],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a model with a speed head")
    parser.add_argument("--baseline", help="a one-output model, driven with slow_in_curves")
    parser.add_argument("--steering-filter", type=float, default=0.0, metavar="S")
    parser.add_argument("--steering-hold", type=float, default=0.0, metavar="H")
    parser.add_argument("--mirror-average", action="store_true",
                        help="average each frame's prediction with its mirror image's")
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--max-seconds", type=float, default=None,
                        help="cap each episode (a quick check of the script, not the targets)")
    parser.add_argument("--out", type=Path, default=None, help="keep bench folders here")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as temporary:
        out = args.out or Path(temporary)
        out.mkdir(parents=True, exist_ok=True)
        suite = suite_at_cap(out)
        figures = {"speed_head": summary(run_bench(
            args.model, suite, out / "speed_head", slow_in_curves=False, workers=args.workers,
            steering_filter_s=args.steering_filter, steering_hold=args.steering_hold,
            mirror_average=args.mirror_average, max_seconds=args.max_seconds))}
        if args.baseline:
            figures["baseline_slow_in_curves"] = summary(run_bench(
                args.baseline, suite, out / "baseline", slow_in_curves=True,
                workers=args.workers, steering_filter_s=args.steering_filter,
                steering_hold=args.steering_hold, mirror_average=args.mirror_average,
                max_seconds=args.max_seconds))
    for name, result in figures.items():
        print(f"{name}: {result['clean_runs']}/{result['runs']} clean (mountain clean: "
              f"{result['mountain_clean']}), lap time vs expert mean "
              f"{result['mean_lap_time_ratio']} max {result['max_lap_time_ratio']} "
              f"(target <= 1.05), smoothness ratio {result['mean_smoothness_ratio']} "
              f"(target <= 1.2)")
        others = ", ".join(f"{name} {value}" for name, value in
                           result["mean_smoothness_ratios_other"].items())
        print(f"  other smoothness figures vs the expert (mean ratio): {others}")
        for split, values in result["splits"].items():
            print(f"  {split:<20} {values}")
        print(f"  slowest lap against the expert: {result['slowest']}")
        if result["failed"]:
            print(f"  not clean: {', '.join(result['failed'])}")
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
