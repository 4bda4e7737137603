"""Closed-loop evaluation: a network drives the simulator, headless and in-process (no socket).

Several runs (track x speed) are driven in lock-step so that their center frames go through the
network as one batch per control step: single-frame Keras calls dominate otherwise. Each run has
its own simulator and its own PI speed controller; steering comes from the shared network.

On an off-road event the frame the network saw is saved, and the car is put back on the
centreline heading along the road at the set speed (an intervention, DESIGN.md); driving goes on
until the target number of laps has been driven or the time limit passes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clonedrive.config import save_config, write_json_atomic
from clonedrive.evaluate.metrics import RunTrace
from clonedrive.udacity_spec import SPEED_KI, SPEED_KP
from clonedrive.world.vehicle import MPH_TO_MPS

#: Generated tracks used as unseen tracks start at this seed; recordings never use them.
UNSEEN_SEED_BASE = 1000


@dataclass(frozen=True)
class EvalConfig:
    """What ``clonedrive evaluate`` runs."""

    tracks: tuple[str, ...] = ("lake",)
    speeds_mph: tuple[float, ...] = (15.0,)
    laps: int = 2
    unseen: int = 0  #: also drive this many generated tracks never used in recording
    unseen_speed_mph: float | None = None  #: speed on unseen tracks (default: the first speed)
    unseen_laps: int | None = None  #: laps on unseen tracks (default: laps)
    video: bool = False
    slow_in_curves: bool = False  #: target speed falls as the predicted steering grows
    scenery: bool = True
    batch: int = 8  #: runs driven in lock-step (their frames batched through the network)
    time_limit_factor: float = 2.5  #: stop after this x the time the laps take at set speed
    max_seconds: float | None = None  #: cap on simulated time per run (quick checks)


@dataclass(frozen=True)
class RunSpec:
    track: str
    speed_mph: float
    laps: int
    unseen: bool = False


def run_specs(config: EvalConfig) -> list[RunSpec]:
    specs = [RunSpec(t, float(v), config.laps) for t in config.tracks for v in config.speeds_mph]
    unseen_speed = config.unseen_speed_mph or config.speeds_mph[0]
    unseen_laps = config.unseen_laps or config.laps
    specs += [RunSpec(f"gen:{UNSEEN_SEED_BASE + i}", float(unseen_speed), unseen_laps, True)
              for i in range(config.unseen)]
    return specs


@dataclass
class _Episode:
    spec: RunSpec
    sim: object
    controller: object
    trace: RunTrace
    name: str
    time_limit_s: float
    video: object = None
    obs: object = None
    done: bool = False
    frames_dir: Path | None = None
    pending_hud: list = field(default_factory=list)


def _run_name(spec: RunSpec) -> str:
    return f"{spec.track.replace(':', '_')}_{spec.speed_mph:g}mph"


def hud_frame(image: np.ndarray, *, steering: float, speed_mph: float, cte_m: float, lap: int,
              laps: int, interventions: int, scale: int = 2) -> np.ndarray:
    """The camera frame enlarged with a heads-up display (steering bar, speed, CTE, lap)."""
    import cv2

    frame = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    height, width = frame.shape[:2]
    overlay = frame.copy()
    cv2.rectangle(overlay, (0, 0), (width, 58), (0, 0, 0), -1)
    frame = cv2.addWeighted(overlay, 0.55, frame, 0.45, 0)
    text = (f"steer {steering:+.2f}  {speed_mph:4.1f} mph  CTE {cte_m:+.2f} m  "
            f"lap {min(lap + 1, laps)}/{laps}  int. {interventions}")
    cv2.putText(frame, text, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.62, (255, 255, 255), 2,
                cv2.LINE_AA)
    # Steering bar: centre tick, filled to the commanded side.
    bar_y, mid, half = 44, width // 2, width // 3
    cv2.line(frame, (mid - half, bar_y), (mid + half, bar_y), (180, 180, 180), 1)
    cv2.line(frame, (mid, bar_y - 5), (mid, bar_y + 5), (255, 255, 255), 1)
    end = int(mid + half * max(-1.0, min(1.0, steering)))
    cv2.line(frame, (mid, bar_y), (end, bar_y), (255, 200, 0), 4)
    return frame


def evaluate(policy, config: EvalConfig, out_dir: str | Path, *, progress: bool = True,
             model_path: str | None = None) -> dict:
    """Drive every run of ``config`` with ``policy`` (a NetworkPolicy) and write the results.

    Writes ``eval.json``, ``config.json``, a map PNG per run, off-road frames and (with
    ``video``) an mp4 per built-in-track run, under ``out_dir``. Returns the eval.json content.
    """
    from clonedrive.progress import progress_bar

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    specs = run_specs(config)
    if not specs:
        raise ValueError("nothing to evaluate: give at least one track (or --unseen N)")
    results: list[dict] = []
    total_steps = sum(_expected_steps(spec, config) for spec in specs)
    bar = progress_bar(total=total_steps, unit="step", desc="evaluate", enabled=progress)
    try:
        for start in range(0, len(specs), max(1, config.batch)):
            group = specs[start:start + max(1, config.batch)]
            results += _drive_group(policy, group, config, out, bar)
    finally:
        bar.close()
    speed_head = bool(getattr(policy, "speed_head", False))
    report = {
        "model": model_path,
        "slow_in_curves": config.slow_in_curves,
        "speed_head": speed_head,
        "speed_control": f"PI (kp {SPEED_KP}, ki {SPEED_KI})"
                         + (", target speed learned (speed head), capped by the set speed"
                            if speed_head else "")
                         + (", target speed reduced with |steering|" if config.slow_in_curves
                            else ""),
        "runs": results,
        "totals": _totals(results),
    }
    save_config(config, out / "config.json")
    write_json_atomic(out / "eval.json", report)
    return report


def _expected_steps(spec: RunSpec, config: EvalConfig) -> int:
    from clonedrive.world.catalog import load_track

    length = load_track(spec.track).length_m
    seconds = spec.laps * length / max(spec.speed_mph * MPH_TO_MPS * 0.85, 1.0)
    if config.max_seconds is not None:
        seconds = min(seconds, config.max_seconds)
    return int(seconds * 15)


def _open_episode(spec: RunSpec, policy, config: EvalConfig, out: Path) -> _Episode:
    from clonedrive.drivers.network import SpeedController
    from clonedrive.sim.simulator import SimConfig, Simulator

    sim = Simulator(spec.track, SimConfig(cameras=("center",), scenery=config.scenery))
    obs, _ = sim.reset(seed=0)
    controller = SpeedController(spec.speed_mph, kp=policy.controller.kp, ki=policy.controller.ki)
    trace = RunTrace(track=spec.track, speed_mph=spec.speed_mph, laps_target=spec.laps,
                     control_hz=sim.config.control_hz, unseen=spec.unseen)
    laps_time = spec.laps * sim.track.length_m / (spec.speed_mph * MPH_TO_MPS)
    name = _run_name(spec)
    time_limit = config.time_limit_factor * laps_time + 30.0
    if config.max_seconds is not None:
        time_limit = min(time_limit, config.max_seconds)
    episode = _Episode(spec=spec, sim=sim, controller=controller, trace=trace, name=name,
                       time_limit_s=time_limit, obs=obs)
    if config.video and not spec.unseen:
        from clonedrive.evaluate.video import VideoWriter

        episode.video = VideoWriter(out / f"{name}.mp4", fps=sim.config.control_hz)
    return episode


def _drive_group(policy, specs: list[RunSpec], config: EvalConfig, out: Path, bar) -> list[dict]:
    from clonedrive.sim.simulator import Controls

    episodes = [_open_episode(spec, policy, config, out) for spec in specs]
    try:
        active = list(episodes)
        while active:
            frames = np.stack([ep.obs.images["center"] for ep in active])
            steering, learned = policy.predict(frames)
            for index, (episode, steer) in enumerate(zip(active, steering, strict=True)):
                target = policy.target_speed_mph(
                    float(steer), set_speed_mph=episode.spec.speed_mph,
                    learned_speed_mph=None if learned is None else float(learned[index]))
                episode.controller.set_speed_mph = target
                throttle = episode.controller.update(episode.obs.speed_mph)
                _step(episode, Controls(steering=float(steer), throttle=throttle), out)
            bar.update(len(active))
            active = [ep for ep in active if not ep.done]
        return [_finish(ep, out) for ep in episodes]
    finally:
        for episode in episodes:
            if episode.video is not None:
                episode.video.close()
            episode.sim.close()


def _step(episode: _Episode, controls, out: Path) -> None:
    sim, trace, spec = episode.sim, episode.trace, episode.spec
    seen = episode.obs.images["center"]
    obs, info = sim.step(controls)
    trace.add_step(obs, controls.steering)
    if episode.video is not None:
        episode.video.append(hud_frame(
            seen, steering=controls.steering, speed_mph=obs.speed_mph, cte_m=obs.cte_m,
            lap=sim.laps_started, laps=spec.laps, interventions=len(trace.off_road)))
    for event in info["events"]:
        frame_png = _save_frame(obs.images["center"], out / "off_road" /
                                f"{episode.name}_{len(trace.off_road) + 1:03d}.png")
        trace.add_off_road(event, frame_png=str(frame_png.relative_to(out)))
        obs = sim.intervene(spec.speed_mph)
        episode.controller.reset()
    trace.laps_completed = obs.laps
    trace.distance_m = obs.distance_m
    episode.obs = obs
    if sim.laps_started >= spec.laps:
        episode.done = True
    elif obs.time_s >= episode.time_limit_s:
        episode.done = True
        trace.timed_out = True


def _save_frame(image: np.ndarray, path: Path) -> Path:
    import cv2

    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    return path


def _finish(episode: _Episode, out: Path) -> dict:
    from clonedrive.evaluate.maps import plot_track_map

    trace = episode.trace
    summary = trace.summary()
    off_xy = np.array([(e.x_m, e.y_m) for e in trace.off_road]).reshape(-1, 2)
    map_path = plot_track_map(
        episode.sim.track, out / f"{episode.name}_map.png",
        title=(f"{trace.track} at {trace.speed_mph:g} mph: {trace.laps_completed}/"
               f"{trace.laps_target} laps, {len(trace.off_road)} interventions"),
        driven_xy=np.column_stack([trace.x_m, trace.y_m]), abs_cte_m=np.abs(trace.cte_m),
        off_road_xy=off_xy)
    summary["map_png"] = str(map_path.relative_to(out))
    if episode.video is not None:
        summary["video"] = f"{episode.name}.mp4"
    return summary


def _totals(results: list[dict]) -> dict:
    def group(rows):
        laps_target = sum(r["laps_target"] for r in rows)
        laps = sum(min(r["laps_completed"], r["laps_target"]) for r in rows)
        return {
            "runs": len(rows),
            "laps_completed": laps,
            "laps_target": laps_target,
            "laps_completed_pct": round(100.0 * laps / laps_target, 1) if laps_target else 0.0,
            "interventions": sum(r["interventions"] for r in rows),
        }

    seen = [r for r in results if not r["unseen"]]
    unseen = [r for r in results if r["unseen"]]
    totals = {"all": group(results)}
    if seen:
        totals["builtin"] = group(seen)
    if unseen:
        totals["unseen"] = group(unseen)
    return totals


def format_table(report: dict) -> str:
    """The printed results table."""
    head = (f"{'track':<10}{'mph':>5}{'laps':>7}{'interv.':>9}{'auton.%':>9}{'mean|CTE|':>10}"
            f"{'max|CTE|':>9}{'smooth':>8}{'speed':>7}{'dist m':>8}")
    lines = [head, "-" * len(head)]
    for r in report["runs"]:
        laps = f"{r['laps_completed']}/{r['laps_target']}"
        lines.append(
            f"{r['track']:<10}{r['speed_mph']:>5g}{laps:>7}{r['interventions']:>9}"
            f"{r['autonomy_pct']:>9.1f}{r['mean_abs_cte_m']:>10.2f}{r['max_abs_cte_m']:>9.2f}"
            f"{r['smoothness']:>8.2f}{r['mean_speed_mph']:>7.1f}{r['distance_m']:>8.0f}")
    for key, total in report["totals"].items():
        lines.append(f"{key}: {total['laps_completed']}/{total['laps_target']} laps "
                     f"({total['laps_completed_pct']:.0f} %), {total['interventions']} "
                     "interventions")
    return "\n".join(lines)


def is_finite_report(report: dict) -> bool:
    """True when every figure in the report is a finite number (a sanity check for tests)."""
    for run in report["runs"]:
        for key in ("autonomy_pct", "mean_abs_cte_m", "max_abs_cte_m", "smoothness"):
            if not math.isfinite(run[key]):
                return False
    return True
