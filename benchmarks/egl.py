"""The two renderers against each other: EGL (OpenGL) frames/s / software frames/s, one run.

``egl_ratio``: camera frames per second (wall clock) of the 3-camera Udacity rig at 320x160,
full scenery, driving along the centreline at 30 mph, drawn through EGL / through the software
renderer (p3tinydisplay), on lake and mountain, alternating pairs in one run (the median pair's
ratio per track; the slower track's ratio is reported). On a machine without a GPU EGL runs on
Mesa's llvmpipe and the ratio is below 1; on a GPU it should be far above. Also reported: the GL
renderer string, what ``auto`` picks here, and ``egl_ratio_crop``: the same with only the write-up
crop's rows (80-135) rendered.

    python benchmarks/egl.py [--steps 300]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

from clonedrive.base.udacity_spec import CONTROL_HZ
from clonedrive.world.vehicle import MPH_TO_MPS

PAIRS = 3


def frames_per_s(track, renderer: str, steps: int, rows=None, warmup: int = 10) -> float:
    """Camera frames/s (wall clock) of the 3-camera rig along ``track`` drawn by ``renderer``."""
    from clonedrive.sim.cameras import CameraRig
    from clonedrive.sim.scene import Scene

    step_m = 30.0 * MPH_TO_MPS / CONTROL_HZ
    with Scene(track, renderer=renderer) as scene, CameraRig(scene, rows=rows) as rig:

        def drive(count: int, start_m: float) -> None:
            for i in range(count):
                s = start_m + i * step_m
                x, y, z = track.point(s)
                rig.render(float(x), float(y), float(z), float(track.heading_at(s)),
                           pitch_rad=float(track.grade(s)))

        drive(warmup, 0.0)
        start = time.perf_counter()
        drive(steps, warmup * step_m)
        return steps * len(rig.cameras) / (time.perf_counter() - start)


def ratio(track, steps: int, rows=None) -> tuple[float, list]:
    pairs = [(frames_per_s(track, "egl", steps, rows), frames_per_s(track, "software", steps, rows))
             for _ in range(PAIRS)]
    return statistics.median(egl / software for egl, software in pairs), pairs


def main() -> None:
    from clonedrive.sim.engine import probe_egl, resolve_renderer
    from clonedrive.world.catalog import load_track

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=300, help="control steps per measurement")
    args = parser.parse_args()
    gl = probe_egl()
    if gl is None:
        print("EGL does not open here: no egl_ratio")
        print(json.dumps({"egl_ratio": None, "gl_renderer": None}))
        return
    load = os.getloadavg()[0]
    print(f"load average before: {load:.2f} on {os.cpu_count()} CPUs; EGL renderer: {gl}; "
          f"auto picks {resolve_renderer('auto')}")
    figures = {}
    for name in ("lake", "mountain"):
        track = load_track(name)
        full, pairs = ratio(track, args.steps)
        crop, crop_pairs = ratio(track, args.steps, rows=(80, 135))
        figures[name] = {"egl_ratio": round(full, 3), "egl_ratio_crop": round(crop, 3),
                         "pairs": [[round(a, 1), round(b, 1)] for a, b in pairs],
                         "crop_pairs": [[round(a, 1), round(b, 1)] for a, b in crop_pairs]}
        print(f"{name:9s} EGL / software camera frames/s: "
              + ", ".join(f"{a:.0f} / {b:.0f}" for a, b in pairs)
              + f" -> egl_ratio {full:.2f}; rows 80-135 only: "
              + ", ".join(f"{a:.0f} / {b:.0f}" for a, b in crop_pairs)
              + f" -> {crop:.2f}")
    print(json.dumps({
        "egl_ratio": min(f["egl_ratio"] for f in figures.values()),
        "egl_ratio_crop": min(f["egl_ratio_crop"] for f in figures.values()),
        "per_track": figures, "gl_renderer": gl, "auto_picks": resolve_renderer("auto"),
        "load_average": round(load, 2)}))


if __name__ == "__main__":
    main()
