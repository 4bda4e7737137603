"""Rendered camera frames per second: headless, one process, the 3-camera Udacity rig at
320x160 on the lake and mountain tracks with full scenery, the car driving along the centreline
at 30 mph with 15 control steps per second.

Prints figures per track (wall-clock and this process's CPU time: other work on the machine
slows the wall clock, not the CPU figure) and ends with one JSON line:
``{"camera_frames_per_s": <slower track, wall clock>, "per_track": {...}, ...}``.

    python benchmarks/render.py [--steps 600] [--tracks lake mountain]
"""

from __future__ import annotations

import argparse
import json
import os
import time


def measure(track_name: str, steps: int, warmup: int = 20) -> dict:
    from clonedrive.sim.cameras import CameraRig
    from clonedrive.sim.scene import Scene
    from clonedrive.world.catalog import load_track

    track = load_track(track_name)
    step_m = 30.0 * 0.44704 / 15.0  # 30 mph at 15 Hz
    build_start = time.perf_counter()
    with Scene(track) as scene, CameraRig(scene) as rig:
        build_s = time.perf_counter() - build_start

        def drive(count: int, start_m: float) -> None:
            for i in range(count):
                s = start_m + i * step_m
                x, y, z = track.point(s)
                grade = float(track.grade(s))
                rig.render(float(x), float(y), float(z), float(track.heading_at(s)),
                           pitch_rad=float(grade))

        drive(warmup, 0.0)
        wall_start, cpu_start = time.perf_counter(), time.process_time()
        drive(steps, warmup * step_m)
        wall_s = time.perf_counter() - wall_start
        cpu_s = time.process_time() - cpu_start
        cameras = len(rig.cameras)
        triangles = scene.triangle_count
    return {
        "track": track_name,
        "steps": steps,
        "cameras": cameras,
        "build_s": round(build_s, 2),
        "triangles": triangles,
        "steps_per_s": steps / wall_s,
        "camera_frames_per_s": steps * cameras / wall_s,
        "cpu_camera_frames_per_s": steps * cameras / cpu_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=600, help="control steps per track")
    parser.add_argument("--tracks", nargs="+", default=["lake", "mountain"])
    args = parser.parse_args()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"load average before: {load:.2f} on {os.cpu_count()} CPUs")
    results = {}
    for name in args.tracks:
        result = measure(name, args.steps)
        results[name] = result
        print(
            f"{name:10s} {result['triangles']:6d} triangles, built in {result['build_s']:.2f} s: "
            f"{result['steps_per_s']:6.1f} three-camera steps/s = "
            f"{result['camera_frames_per_s']:6.1f} camera frames/s wall clock, "
            f"{result['cpu_camera_frames_per_s']:6.1f} per CPU second"
        )
    slowest = min(results.values(), key=lambda r: r["camera_frames_per_s"])
    print(json.dumps({
        "camera_frames_per_s": round(slowest["camera_frames_per_s"], 1),
        "per_track": {name: round(r["camera_frames_per_s"], 1) for name, r in results.items()},
        "cpu_camera_frames_per_s": {
            name: round(r["cpu_camera_frames_per_s"], 1) for name, r in results.items()
        },
        "load_average": round(load, 2),
    }))


if __name__ == "__main__":
    main()
