"""Rendering only the rows the network sees: what it changes in the pixels, and what it gains.

- ``crop_pixels``: along a whole lap of lake and mountain (the centreline, a frame every
  ``STEP_M``), the rows a crop keeps rendered alone (``CameraRig(rows=...)``) against the same
  rows of the full 160x320 frame: the largest difference of any channel, the mean absolute
  difference, and the share of pixels that differ at all. For the write-up's crop (rows 80-135)
  and ``--crop-top 60`` (rows 60-135).
- ``crop_speedup``: ``clonedrive evaluate``'s steps/s with the crop / with ``--full-frame``, 8
  cars in lock-step on the lake for 60 s each, the demo's network (``fast``; its weights do not
  change the cost), alternating pairs in one run, the median pair's ratio. For crop tops 80 and
  60. Beside it the same per CPU second of this process (``crop_speedup_cpu_*``: other work on a
  shared machine slows it less) and for the steady loop alone, simulators built, no map plots
  (``crop_speedup_steady_*``).
- ``loop_ratio_crop``: the cropped closed loop's steps/s / render-only steps/s of full frames of
  the center camera on the same track (``benchmarks/evaluate.py``'s ``loop_ratio`` reference).
- ``crop_driving``: a model (the argument, e.g. the demo's model.keras; default: none, skipped)
  evaluated on lake and mountain (1 lap, 15 mph) cropped and full-frame with the software
  renderer, and cropped with EGL: laps, interventions, mean and max |CTE|.

Run: python benchmarks/crop.py [MODEL.keras|-] [pixels] [speed] [driving]   (default: all parts)
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

#: Distance between the frames compared along the lap [m].
STEP_M = 2.0
#: The crops measured: the write-up's (rows 80-135) and --crop-top 60's.
CROPS = {"80": (80, 135), "60": (60, 135)}
PAIRS = 3


def poses(track, step_m: float = STEP_M):
    """Poses along the centreline of a whole lap, a frame every ``step_m``."""
    import numpy as np

    for s in np.arange(0.0, track.length_m, step_m):
        x, y, z = track.point(float(s))
        yield float(x), float(y), float(z), float(track.heading_at(s)), float(track.grade(s))


def crop_pixels(track_name: str, rows: tuple[int, int]) -> dict:
    """The crop's rows rendered alone against the same rows of full frames, over a lap."""
    import numpy as np

    from clonedrive.sim.cameras import CameraRig
    from clonedrive.sim.scene import Scene
    from clonedrive.world.catalog import load_track

    track = load_track(track_name)
    top, bottom = rows
    worst, total, differing, pixels, frames = 0, 0.0, 0, 0, 0
    with Scene(track, renderer="software") as scene, \
            CameraRig(scene, cameras=("center",)) as full, \
            CameraRig(scene, cameras=("center",), rows=rows) as cropped:
        for x, y, z, heading, grade in poses(track):
            a = full.render(x, y, z, heading, grade)["center"][top:bottom].astype(np.int16)
            b = cropped.render(x, y, z, heading, grade)["center"][top:bottom].astype(np.int16)
            difference = np.abs(a - b)
            worst = max(worst, int(difference.max()))
            total += float(difference.mean())
            differing += int((difference.max(axis=2) > 0).sum())
            pixels += difference.shape[0] * difference.shape[1]
            frames += 1
    return {"frames": frames, "max_difference": worst,
            "mean_abs_difference": round(total / frames, 3),
            "differing_pixels_pct": round(100.0 * differing / pixels, 2)}


def evaluate_steps_per_s(policy, full_frame: bool, seconds: float = 60.0
                         ) -> tuple[float, int, float]:
    """evaluate's steps/s: 8 cars in lock-step on the lake, ``seconds`` each; also steps per
    CPU second of this process (both its threads), which other work on the machine slows
    less."""
    from clonedrive.evaluate.rollout import EvalConfig, evaluate

    speeds = tuple(20.0 + 0.5 * i for i in range(8))
    config = EvalConfig(tracks=("lake",), speeds_mph=speeds, laps=1, batch=8,
                        max_seconds=seconds, expert_reference=False, full_frame=full_frame,
                        renderer="software")
    with tempfile.TemporaryDirectory() as out:
        start, cpu = time.perf_counter(), time.process_time()
        report = evaluate(policy, config, out, progress=False)
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    steps = sum(round(run["elapsed_s"] * 15) for run in report["runs"])
    return steps / wall, steps, steps / cpu


def steady_steps_per_s(policy, rows, seconds: float = 20.0) -> float:
    """Steps/s of 8 cars in lock-step once their simulators are built (no scene builds, no map
    plots), the network on a second thread as evaluate runs it, frames of ``rows``."""
    from evaluate import steady_loop_steps_per_s

    return steady_loop_steps_per_s(policy, 8, seconds, rows=rows, renderer="software")


def crop_speedup(crop_top: int) -> tuple[float, list, float, float, float]:
    """(speedup, pairs, loop_ratio with the crop, speedup in steps per CPU second, speedup of
    the steady loop) for the ``fast`` network cropping at ``crop_top``."""
    import numpy as np
    from evaluate import render_only_steps_per_s

    from clonedrive.base.udacity_spec import IMAGE_SHAPE
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.model.architectures import build_model

    policy = NetworkPolicy(build_model("fast", crop_top_px=crop_top), set_speed_mph=20.0)
    policy.predict_steering(np.zeros((8, *IMAGE_SHAPE), np.uint8))  # warm up
    pairs, loops, cpu, steady = [], [], [], []
    for _ in range(PAIRS):
        rows = (crop_top, 135)
        steady.append(steady_steps_per_s(policy, rows) / steady_steps_per_s(policy, None))
        cropped, steps, cropped_cpu = evaluate_steps_per_s(policy, full_frame=False)
        full, _, full_cpu = evaluate_steps_per_s(policy, full_frame=True)
        pairs.append((cropped, full))
        cpu.append(cropped_cpu / full_cpu)
        loops.append(cropped / render_only_steps_per_s(steps))
    speedup = statistics.median(c / f for c, f in pairs)
    return (speedup, pairs, statistics.median(loops), statistics.median(cpu),
            statistics.median(steady))


def crop_driving(model_path: str) -> dict:
    """The model's runs on lake and mountain (1 lap, 15 mph): cropped and full-frame with the
    software renderer, and cropped with EGL (where it opens)."""
    from clonedrive.drivers.policy import load_policy
    from clonedrive.evaluate.rollout import EvalConfig, evaluate
    from clonedrive.sim.engine import probe_egl

    policy = load_policy(model_path)
    found = {}
    ways = [("software", False), ("software", True)]
    if probe_egl() is not None:
        ways.append(("egl", False))
    for renderer, full_frame in ways:
        config = EvalConfig(tracks=("lake", "mountain"), speeds_mph=(15.0,), laps=1,
                            expert_reference=False, full_frame=full_frame,
                            renderer=renderer, workers=1)
        with tempfile.TemporaryDirectory() as out:
            report = evaluate(policy, config, out, progress=False)
        found[f"{renderer}_{'full_frame' if full_frame else 'cropped'}"] = [
            {key: run[key] for key in ("track", "laps_completed", "interventions",
                                       "mean_abs_cte_m", "max_abs_cte_m")}
            for run in report["runs"]]
    return found


def main() -> None:
    figures: dict = {}
    parts = sys.argv[2:] or ["pixels", "speed", "driving"]
    for name, rows in CROPS.items() if "pixels" in parts else ():
        for track in ("lake", "mountain"):
            found = crop_pixels(track, rows)
            figures[f"crop_pixels_{track}_{name}"] = found
            print(f"crop rows {rows[0]}-{rows[1]}, {track}, {found['frames']} frames: max "
                  f"difference {found['max_difference']}, mean {found['mean_abs_difference']}, "
                  f"{found['differing_pixels_pct']} % of pixels differ")
    for name in CROPS if "speed" in parts else ():
        speedup, pairs, loop, cpu, steady = crop_speedup(int(name))
        listed = ", ".join(f"{c:.0f} / {f:.0f}" for c, f in pairs)
        print(f"evaluate, 8 cars, fast network, crop top {name}: cropped / full-frame steps/s "
              f"{listed} -> crop_speedup {speedup:.2f} (per CPU second {cpu:.2f}; the steady "
              f"loop alone {steady:.2f}); loop_ratio with the crop {loop:.2f}")
        figures[f"crop_speedup_steady_{name}"] = round(steady, 3)
        figures[f"crop_speedup_{name}"] = round(speedup, 3)
        figures[f"crop_speedup_cpu_{name}"] = round(cpu, 3)
        figures[f"loop_ratio_crop_{name}"] = round(loop, 3)
    if "speed" in parts:
        figures["crop_speedup"] = figures["crop_speedup_80"]
        figures["loop_ratio"] = figures["loop_ratio_crop_80"]
    if len(sys.argv) > 1 and sys.argv[1] != "-" and "driving" in parts:
        driving = crop_driving(sys.argv[1])
        for kind, runs in driving.items():
            for run in runs:
                print(f"{kind:>10}: {run}")
        figures["crop_driving"] = driving
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
