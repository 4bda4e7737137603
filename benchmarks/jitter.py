"""Steering jitter in open loop: how much of a model's steering rate is its own frame-to-frame
noise, apart from how it drives.

The expert drives each benchmark track (suite v2's train-tracks and new-tracks easy/medium/hard,
as ``speed_head.py`` drives them) at the 30 mph cap with no noise; on every frame the model
predicts a steering, and the expert's clean label for that same frame is the reference, measured
in the same run. Per track:

- ``jitter_ratio``: the prediction's steering rate (mean |change| per second, the ``smoothness``
  figure of eval.json) over the label's. 1.0 is a model that varies its steering along the
  expert's path no more than the expert does;
- ``slow_ratio``: the same for both signals low-passed at 0.5 s (forward and backward, no lag):
  the part of the rate that follows the road rather than the frame;
- ``residual_rms``: RMS of prediction - label (steering units).

A closed-loop smoothness ratio (``speed_head.py``) mixes this noise with how the car then moves;
a ``jitter_ratio`` far above ``slow_ratio`` says the excess is noise in the network's output,
which no driving of the road explains, and which filtering the wheel can only trade for delay.

Ends with one JSON line: ``{"jitter_ratio": <mean over tracks>, "slow_ratio": ...,
"residual_rms": ..., "tracks": {...}}``.

    python benchmarks/jitter.py MODEL [--tracks T ...] [--max-seconds 60] [--mirror-average]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

#: Time constant [s] of the zero-phase low-pass that separates "follows the road" from jitter.
SLOW_TIME_CONSTANT_S = 0.5
#: Frames predicted at once.
CHUNK = 64


def benchmark_tracks() -> list[str]:
    """The tracks ``speed_head.py`` drives: suite v2's track splits."""
    from speed_head import SPLITS

    from clonedrive.bench import DEFAULT_SUITE
    from clonedrive.bench.suite import load_suite

    tracks: list[str] = []
    for split in load_suite(DEFAULT_SUITE).to_dict()["splits"]:
        if split["name"] in SPLITS:
            tracks += [name for name in split["tracks"] if name not in tracks]
    return tracks


def zero_phase_low_pass(values: np.ndarray, time_constant_s: float, hz: float) -> np.ndarray:
    """The policy's steering low-pass (:class:`SteeringFilter`, no hold) run forward, then
    backward over the result: the same smoothing with no delay."""
    from clonedrive.drivers.policy import SteeringFilter

    def run(series: np.ndarray) -> np.ndarray:
        low_pass = SteeringFilter(time_constant_s, control_hz=hz)
        return np.array([low_pass.update(value) for value in series])

    forward = run(np.asarray(values, dtype=float))
    return run(forward[::-1])[::-1]


def drive_track(policy, track: str, speed_mph: float, max_seconds: float) -> dict:
    """The expert drives one lap (or ``max_seconds``); the model predicts on each frame."""
    from clonedrive.base.udacity_spec import CONTROL_HZ
    from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy
    from clonedrive.episode.trace import smoothness
    from clonedrive.sim.simulator import SimConfig, Simulator

    sim = Simulator(track, SimConfig(cameras=("center",)))
    try:
        obs, _ = sim.reset(seed=0)
        expert = ExpertPolicy(sim.track, ExpertConfig(speed_mph=speed_mph))
        expert.reset()
        labels, predictions, frames = [], [], []
        while obs.laps < 1 and obs.time_s < max_seconds:
            action = expert.act(obs)
            labels.append(action.label_steering)
            frames.append(obs.images["center"])
            if len(frames) == CHUNK:
                predictions.extend(policy.predict_steering(np.stack(frames)).tolist())
                frames.clear()
            obs, _ = sim.step(action.controls_applied)
        if frames:
            predictions.extend(policy.predict_steering(np.stack(frames)).tolist())
    finally:
        sim.close()
    label, prediction = np.asarray(labels), np.asarray(predictions)
    slow_label = zero_phase_low_pass(label, SLOW_TIME_CONSTANT_S, CONTROL_HZ)
    slow_prediction = zero_phase_low_pass(prediction, SLOW_TIME_CONSTANT_S, CONTROL_HZ)
    label_rate = smoothness(label, CONTROL_HZ)
    prediction_rate = smoothness(prediction, CONTROL_HZ)
    slow_label_rate = smoothness(slow_label, CONTROL_HZ)
    return {
        "frames": len(label),
        "label_rate_per_s": round(label_rate, 4),
        "prediction_rate_per_s": round(prediction_rate, 4),
        "jitter_ratio": round(prediction_rate / label_rate, 3)
        if label_rate else None,
        "slow_ratio": round(smoothness(slow_prediction, CONTROL_HZ) / slow_label_rate, 3)
        if slow_label_rate else None,
        "residual_rms": round(float(np.sqrt(np.mean((prediction - label) ** 2))), 4),
    }


def mean_of(results: dict, key: str) -> float | None:
    values = [r[key] for r in results.values() if r[key] is not None]
    return round(sum(values) / len(values), 3) if values else None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a model file (.keras, .h5, .onnx)")
    parser.add_argument("--tracks", nargs="+", default=None,
                        help="tracks to drive (default: the benchmark's 14)")
    parser.add_argument("--speed", type=float, default=30.0, help="set speed, mph (default 30)")
    parser.add_argument("--max-seconds", type=float, default=60.0,
                        help="simulated seconds per track at most (default 60)")
    parser.add_argument("--mirror-average", action="store_true",
                        help="the policy averages each frame's prediction with its mirror's")
    args = parser.parse_args()
    from tqdm import tqdm

    from clonedrive.drivers.policy import load_policy

    policy = load_policy(args.model, mirror_average=args.mirror_average)
    tracks = args.tracks or benchmark_tracks()
    results = {}
    for track in tqdm(tracks, desc="jitter", unit="track"):
        results[track] = drive_track(policy, track, args.speed, args.max_seconds)
    print(f"{'track':<18} {'frames':>6} {'label/s':>8} {'pred/s':>8} {'jitter':>7} "
          f"{'slow':>6} {'resid':>6}")
    for track, r in results.items():
        print(f"{track:<18} {r['frames']:>6} {r['label_rate_per_s']:>8.4f} "
              f"{r['prediction_rate_per_s']:>8.4f} {r['jitter_ratio'] or 0:>7.2f} "
              f"{r['slow_ratio'] or 0:>6.2f} {r['residual_rms']:>6.4f}")
    summary = {key: mean_of(results, key) for key in ("jitter_ratio", "slow_ratio",
                                                       "residual_rms")}
    print(f"mean: jitter_ratio {summary['jitter_ratio']} (1.0 = no more than the expert's "
          f"label), slow_ratio {summary['slow_ratio']}, residual_rms {summary['residual_rms']}")
    print(json.dumps({**summary, "tracks": results}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
