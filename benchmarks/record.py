"""Recording speed: samples (rows with 3 camera JPEGs) written to disk per second, on lake.

Run: python benchmarks/record.py [--laps 1] [--speed 30]   (target: >= 150 samples/s, 10x the
15 Hz real-time rate). Also prints where the time goes: rendering the three cameras, the
expert plus physics, JPEG encoding, and an fsync of the CSV, each measured alone.

``record_ratio`` (measured in the same run, so it travels between machines): recorded samples/s
/ render-only samples/s (the simulator stepping its three cameras, nothing written). Target
>= 0.6.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from clonedrive.base.udacity_spec import CONTROL_HZ

TARGET_SAMPLES_PER_S = 150.0


def time_render(steps: int) -> float:
    """Seconds per step of the simulator with its three cameras (no expert, no writing)."""
    from clonedrive.sim.simulator import Controls, SimConfig, Simulator

    with Simulator("lake", SimConfig()) as sim:
        sim.reset(seed=0, options={"speed_mph": 20.0})
        start = time.perf_counter()
        for _ in range(steps):
            sim.step(Controls(throttle=0.2))
        return (time.perf_counter() - start) / steps


def time_state_only(steps: int) -> float:
    """Seconds per step of the expert and the physics without cameras."""
    from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy
    from clonedrive.sim.simulator import SimConfig, Simulator

    with Simulator("lake", SimConfig(cameras=())) as sim:
        expert = ExpertPolicy(sim.track, ExpertConfig(), np.random.default_rng(0))
        obs, _ = sim.reset(seed=0)
        start = time.perf_counter()
        for _ in range(steps):
            obs, _ = sim.step(expert.act(obs).controls_applied)
        return (time.perf_counter() - start) / steps


def time_jpeg(folder: Path, repeats: int) -> float:
    """Seconds to write one rendered 320x160 RGB image as a JPEG at the recorder's quality, the
    recorder's way: BGR view, cv2.imwrite to a temp name, rename."""
    import cv2

    from clonedrive.base.udacity_spec import JPEG_QUALITY
    from clonedrive.data.row_sink import write_jpeg
    from clonedrive.sim.simulator import SimConfig, Simulator

    with Simulator("lake", SimConfig(cameras=("center",))) as sim:
        obs, _ = sim.reset(seed=0)
    image = obs.images["center"]
    params = [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]
    start = time.perf_counter()
    for index in range(repeats):
        write_jpeg(image, folder / f"center_{index}.jpg", params)
    return (time.perf_counter() - start) / repeats


def time_fsync(folder: Path, repeats: int) -> float:
    """Seconds for appending one CSV-sized line and fsync-ing the file."""
    path = folder / "fsync_probe.csv"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    try:
        start = time.perf_counter()
        for _ in range(repeats):
            os.write(fd, b"x" * 200 + b"\n")
            os.fsync(fd)
        return (time.perf_counter() - start) / repeats
    finally:
        os.close(fd)
        path.unlink()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--laps", type=int, default=1)
    parser.add_argument("--speed", type=float, default=30.0)
    args = parser.parse_args()

    from clonedrive.data.driving_log import read_driving_log
    from clonedrive.data.recorder import RecordConfig, record

    with tempfile.TemporaryDirectory(prefix="clonedrive-record-bench-") as tmp:
        out = Path(tmp) / "run"
        config = RecordConfig(track="lake", laps=args.laps, speed_mph=args.speed)
        summary = record(config, out, progress=False)
        log = read_driving_log(out, verify_images="exists")
        assert len(log.rows) == summary.rows and not log.skipped, "benchmark log is not whole"
        fsync_s = time_fsync(Path(tmp), 50)
        jpeg_s = time_jpeg(Path(tmp), 300)
    render_s = time_render(150)
    state_s = time_state_only(600)

    rate = summary.samples_per_s
    print(f"recorded {summary.rows} rows ({summary.laps} lap of lake at <= {args.speed:g} mph) "
          f"in {summary.wall_seconds:.1f} s: {rate:.0f} samples/s "
          f"({rate / CONTROL_HZ:.1f}x the {CONTROL_HZ:g} Hz real-time rate)")
    print("where the time goes, per sample, each part measured alone:")
    print(f"  render 3 cameras + physics  {1000 * render_s:6.2f} ms  "
          f"(ceiling {1 / render_s:.0f} samples/s)")
    print(f"  expert + physics (no render) {1000 * state_s:5.2f} ms")
    print(f"  3 JPEGs encoded + written   {3000 * jpeg_s:6.2f} ms  (writer thread, overlapped)")
    print(f"  CSV line write + fsync      {1000 * fsync_s:6.2f} ms  (fsync every 15 rows only)")
    print(f"recording runs at {100 * rate * render_s:.0f}% of the rendering-only rate")
    print(f"target >= {TARGET_SAMPLES_PER_S:.0f} samples/s: "
          f"{'met' if rate >= TARGET_SAMPLES_PER_S else 'NOT met'} on {os.cpu_count()} CPU(s)")
    print(f"record_ratio {rate * render_s:.2f} (target >= 0.6)")
    print(json.dumps({
        "record_ratio": round(rate * render_s, 3),
        "samples_per_s": round(rate, 1),
        "rows": summary.rows,
        "render_ms_per_sample": round(1000 * render_s, 3),
        "expert_physics_ms_per_step": round(1000 * state_s, 3),
        "jpeg_ms_per_sample": round(3000 * jpeg_s, 3),
        "fsync_ms": round(1000 * fsync_s, 3),
        "fraction_of_render_ceiling": round(rate * render_s, 3),
        "target_samples_per_s": TARGET_SAMPLES_PER_S,
    }))


if __name__ == "__main__":
    main()
