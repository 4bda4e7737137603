"""``replay()``: a model through one or more logs; ``replay.json``, ``replay.png``, the video."""

from __future__ import annotations

import os
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from clonedrive.base.config import atomic_path, write_json_atomic
from clonedrive.base.udacity_spec import CONTROL_HZ
from clonedrive.replay.episode import (
    Episode,
    ReplayConfig,
    calibration_frames,
    drive_episode,
    episode_figures,
    log_path,
    log_sources,
    replayable_episodes,
)
from clonedrive.replay.view import CALIBRATION_FRAMES, Rig, calibrate

JSON_NAME, PLOT_NAME, VIDEO_NAME = "replay.json", "replay.png", "replay.mp4"
HUD_SCALE = 2  #: the video's frames are the synthesised views enlarged this many times


def replay(policy: Any, log_dirs: list[str | os.PathLike], out_dir: str | os.PathLike,
           config: ReplayConfig | None = None, rig: Rig | None = None, *,
           video: bool = False, model_path: str | None = None) -> dict:
    """Replay ``policy`` through each log of ``log_dirs`` (every log is checked before any is
    driven); write the figures, the plot and optionally the video into ``out_dir``."""
    config, rig = config or ReplayConfig(), rig or Rig()
    prepared = [(Path(log_dir), replayable_episodes(log_dir, config)) for log_dir in log_dirs]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    writer = _video_writer(out / VIDEO_NAME) if video else None
    logs, driven = [], []
    try:
        for log_dir, episodes in prepared:
            entry, log_rig = _log_rig(log_dir, episodes, rig, config)
            hud = None if writer is None else _hud_sink(writer, config)
            for episode in episodes:
                drive_episode(policy, episode, log_rig, config, on_frame=hud)
            entry["episodes"] = [episode_figures(episode, config) for episode in episodes]
            entry["totals"] = totals(entry["episodes"], config)
            logs.append(entry)
            driven.append((log_dir, episodes))
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    files = {"json": JSON_NAME, "plot": PLOT_NAME}
    if writer is not None and writer.close() is not None:
        files["video"] = VIDEO_NAME
    report = {"model": model_path, "config": asdict(config), "logs": logs,
              "totals": totals([entry["totals"] for entry in logs], config), "files": files}
    plot_offsets(out / PLOT_NAME, driven, config)
    write_json_atomic(out / JSON_NAME, report)
    return report


def _log_rig(log_dir: Path, episodes: list[Episode], rig: Rig,
             config: ReplayConfig) -> tuple[dict, Rig]:
    sources = log_sources(episodes)
    three = len(sources) == 3
    if three and config.calibrate:
        rig = calibrate(rig, calibration_frames(episodes, CALIBRATION_FRAMES))
    edges = ("filled from the side cameras" if three else
             "centre-only log: beyond the centre camera's view the edge pixels are repeated")
    entry = {"log": str(log_path(log_dir)), "sources": sources,
             "calibrated": three and config.calibrate, "rig": asdict(rig),
             "max_offset_m": config.max_offset_m, "edges": edges}
    return entry, rig


def totals(parts: list[dict], config: ReplayConfig) -> dict:
    """Figures over several episodes (or logs): sums, and means weighted by frames or time."""
    from clonedrive.replay.episode import autonomy

    elapsed = sum(part["elapsed_s"] for part in parts)
    distance = sum(part["distance_m"] for part in parts)
    count = sum(part["interventions"] for part in parts)
    frames = sum(part["frames"] for part in parts)

    def weighted(key: str, weight: str) -> float | None:
        pairs = [(part[key], part[weight]) for part in parts if part[key] is not None]
        total = sum(size for _, size in pairs)
        return round(sum(value * size for value, size in pairs) / total, 4) if total else None

    return {
        "episodes": sum(part.get("episodes", 1) for part in parts),
        "frames": frames, "elapsed_s": round(elapsed, 3), "distance_m": round(distance, 2),
        "interventions": count,
        "autonomy_pct": autonomy(count, elapsed, config.intervention_penalty_s),
        "interventions_per_km": round(count / (distance / 1000.0), 3) if distance > 0 else None,
        "mean_abs_offset_m": weighted("mean_abs_offset_m", "frames"),
        "max_abs_offset_m": max(part["max_abs_offset_m"] for part in parts),
        "jitter_per_s": weighted("jitter_per_s", "elapsed_s"),
        "human_jitter_per_s": weighted("human_jitter_per_s", "elapsed_s"),
    }


def _video_writer(path: Path):
    from clonedrive.evaluate.video import VideoWriter

    return VideoWriter(path, fps=CONTROL_HZ)


def _hud_sink(writer, config: ReplayConfig):
    def on_frame(view: np.ndarray, episode: Episode) -> None:
        writer.append(hud_frame(view, episode, config))

    return on_frame


def hud_frame(view: np.ndarray, episode: Episode, config: ReplayConfig) -> np.ndarray:
    """The synthesised view, enlarged, with the offset, the two steerings and the count."""
    import cv2

    frame = cv2.resize(view, None, fx=HUD_SCALE, fy=HUD_SCALE, interpolation=cv2.INTER_LINEAR)
    index = len(episode.steering) - 1
    lines = (f"offset {episode.offset_m[-1]:+.2f} m  heading "
             f"{np.degrees(episode.heading_rad[-1]):+.1f} deg",
             f"model {episode.steering[-1]:+.2f}  human {episode.rows[index].steering:+.2f}",
             f"interventions {len(episode.interventions)}  ({episode.distance_m[-1]:.0f} m)")
    for number, text in enumerate(lines):
        origin = (8, 20 + 20 * number)
        cv2.putText(frame, text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 3,
                    cv2.LINE_AA)
        cv2.putText(frame, text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1,
                    cv2.LINE_AA)
    return frame


def plot_offsets(path: Path, driven: list[tuple[Path, list[Episode]]],
                 config: ReplayConfig) -> Path:
    """The offset from the recorded path over distance, episodes one after another, an x at
    each intervention."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    figure, axis = plt.subplots(figsize=(11, 3.6))
    start = 0.0
    for log_dir, episodes in driven:
        for episode in episodes:
            distance = start + np.array(episode.distance_m)
            offsets = np.array(episode.offset_m)
            axis.plot(distance, offsets, color="tab:blue", linewidth=1.0)
            marks = episode.interventions
            axis.plot(distance[marks], np.sign(offsets[marks]) * config.max_offset_m, "x",
                      color="tab:red", markersize=7)
            axis.axvline(start, color="0.6", linestyle=":", linewidth=0.8)
            start = distance[-1]
        axis.text(start, config.max_offset_m * 1.05, f" {log_dir.name}", fontsize=7,
                  ha="right", va="bottom")
    for level in (-config.max_offset_m, config.max_offset_m):
        axis.axhline(level, color="tab:red", linestyle="--", linewidth=0.8)
    axis.set_xlabel("distance along the recorded path [m] (dotted: a new episode)")
    axis.set_ylabel("offset from the path [m], right +")
    axis.set_ylim(-1.25 * config.max_offset_m, 1.25 * config.max_offset_m)
    axis.set_title("replay: offset from the human's path (x: an intervention)", fontsize=10)
    figure.tight_layout()
    try:
        with atomic_path(path) as temporary:
            figure.savefig(temporary, format="png", dpi=110)
    finally:
        plt.close(figure)
    return path


def format_summary(report: dict) -> str:
    """A few lines for the terminal."""
    lines = []
    for entry in report["logs"] + [{"log": "all logs", "totals": report["totals"]}]:
        figures = entry["totals"]
        lines.append(
            f"{entry['log']}: autonomy {figures['autonomy_pct']} %, "
            f"{figures['interventions']} interventions in {figures['distance_m']:.0f} m "
            f"({figures['interventions_per_km']} per km), mean |offset| "
            f"{figures['mean_abs_offset_m']} m, jitter {figures['jitter_per_s']} /s "
            f"(human {figures['human_jitter_per_s']} /s)")
    return "\n".join(lines)
