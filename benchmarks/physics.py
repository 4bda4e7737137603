"""Physics speed: simulated seconds per wall-clock second, vehicle + track queries, no rendering.

Run: python benchmarks/physics.py   (target: >= 200x real time on one core)
"""

from __future__ import annotations

import json
import math
import time

from clonedrive.base.udacity_spec import MAX_WHEEL_ANGLE_DEG
from clonedrive.sim.simulator import Controls, SimConfig, Simulator


def drive(track: str, sim_seconds: float) -> float:
    with Simulator(track, SimConfig(cameras=())) as sim:
        obs, _ = sim.reset(seed=0)
        steps = int(sim_seconds * sim.config.control_hz)
        start = time.perf_counter()
        for _ in range(steps):
            steering = -0.15 * obs.cte_m + 1.2 * obs.heading_error_rad
            steering -= 2.7 * obs.curvature_per_m / math.tan(math.radians(MAX_WHEEL_ANGLE_DEG))
            throttle = 0.3 * (15.0 - obs.speed_mph)
            obs, _ = sim.step(Controls(steering=max(-1, min(1, steering)),
                                       throttle=max(-1, min(1, throttle))))
        wall = time.perf_counter() - start
    return steps / sim.config.control_hz / wall


def main() -> None:
    factors = {track: drive(track, 120.0) for track in ("lake", "mountain")}
    for track, factor in factors.items():
        print(f"{track:<10} {factor:8.0f}x real time (physics at 150 Hz, control at 15 Hz)")
    slower = min(factors.values())
    print(f"target >= 200x: {'met' if slower >= 200 else 'NOT met'}")
    print(json.dumps({"realtime_factor": round(slower, 1),
                      "per_track": {k: round(v, 1) for k, v in factors.items()}}))


if __name__ == "__main__":
    main()
