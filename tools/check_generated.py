"""Check generated tracks: validation, difficulty figures, and the expert driving each cleanly.

Run: python tools/check_generated.py [--seeds N] [--difficulty hard ...] [--speed MPH]
Prints one row per track (length, width, tightest radius, steepest grade, curved share, expert
lap time and off-road events) and a summary line; exits 1 if the expert left the road anywhere.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from clonedrive.drivers.expert import ExpertConfig, ExpertDriver
from clonedrive.sim.simulator import SimConfig, Simulator
from clonedrive.world.catalog import load_track
from clonedrive.world.segments import DIFFICULTIES, curved_fraction


def expert_lap(name: str, speed_mph: float, reverse: bool) -> tuple[float, int, float]:
    """(lap time s, off-road events, max |CTE| m) of the expert's first lap."""
    track = load_track(name)
    expert = ExpertDriver(track, ExpertConfig(speed_mph=speed_mph, reverse=reverse))
    with Simulator(track, SimConfig(cameras=())) as sim:
        obs, _ = sim.reset(seed=0, options={"reverse": reverse})
        worst = 0.0
        while sim.laps_started < 1 and obs.time_s < 900:
            obs, _ = sim.step(expert.act(obs).controls_applied)
            worst = max(worst, abs(obs.cte_m))
        return obs.time_s, obs.off_road_events, worst


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--difficulty", action="append", choices=list(DIFFICULTIES))
    parser.add_argument("--speed", type=float, default=30.0)
    parser.add_argument("--reverse", action="store_true", help="also drive each backwards")
    args = parser.parse_args()
    bad, rows = 0, []
    for difficulty in args.difficulty or list(DIFFICULTIES):
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            name = f"gen2:{difficulty}:{seed}"
            start = time.perf_counter()
            track = load_track(name)
            made_s = time.perf_counter() - start
            for reverse in (False, True) if args.reverse else (False,):
                lap_s, events, worst = expert_lap(name, args.speed, reverse)
                bad += events > 0
                rows.append({"track": name, "reverse": reverse, "theme": track.theme,
                             **{k: v for k, v in track.summary().items()
                                if k in ("length_m", "width_m", "min_radius_m", "max_grade")},
                             "curved": round(curved_fraction(track), 2),
                             "made_s": round(made_s, 2), "expert_lap_s": round(lap_s, 1),
                             "off_road": events, "max_abs_cte_m": round(worst, 2)})
                print(" ".join(f"{k}={v}" for k, v in rows[-1].items()), flush=True)
    print(f"{len(rows)} laps, {bad} with off-road events; worst |CTE| "
          f"{max(r['max_abs_cte_m'] for r in rows):.2f} m; slowest to make "
          f"{max(r['made_s'] for r in rows):.2f} s; mean expert speed "
          f"{np.mean([r['length_m'] / r['expert_lap_s'] for r in rows]) / 0.44704:.1f} mph")
    print(json.dumps({"laps": len(rows), "laps_with_off_road": bad}))
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
