"""A model driven in closed loop through a recorded Udacity log (PilotNet's section 7 method).

The car's state is its lateral offset (right = +) and heading error (right = +) from the path the
human drove. Each frame the model sees the recorded view synthesised for that offset and
heading (:mod:`clonedrive.replay.view`); its steering then moves the car away from the human's
path at the recorded speed, by a kinematic bicycle (or the simulator's dynamic vehicle model:
:mod:`clonedrive.replay.motion`). Past
:attr:`ReplayConfig.max_offset_m` an intervention puts the car back on the path.
Autonomy = (1 - interventions x penalty / elapsed) x 100, floored at 0.

A log splits into episodes where consecutive image timestamps are further apart than
:data:`clonedrive.evaluate.crosscheck.SEGMENT_GAP_S`.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from clonedrive.base.udacity_spec import CONTROL_HZ
from clonedrive.episode.trace import SECONDS_PER_INTERVENTION, autonomy_pct
from clonedrive.evaluate.crosscheck import SEGMENT_GAP_S
from clonedrive.replay.motion import RelativeMotion, check_vehicle_model
from clonedrive.replay.view import Rig, synthesise
from clonedrive.world.vehicle import MPH_TO_MPS

SIDE_CAMERAS = ("left", "right")


class ReplayError(ValueError):
    """A log that cannot be replayed; the message says why."""


@dataclass(frozen=True)
class ReplayConfig:
    """How a replay is run and scored."""

    max_offset_m: float = 1.0  #: an intervention beyond this offset from the path
    intervention_penalty_s: float = SECONDS_PER_INTERVENTION  #: an intervention's cost (PilotNet)
    min_episode_frames: int = 30  #: shorter episodes are left out (2 s at 15 Hz)
    min_distance_m: float = 20.0  #: a log whose car covers less is stationary
    calibrate: bool = True  #: fit the side-camera offsets from the log where it has them
    vehicle_model: str = "kinematic"  #: how the car moves off the path (replay.motion)

    def __post_init__(self) -> None:
        if self.max_offset_m <= 0:
            raise ValueError(f"max_offset_m must be positive, got {self.max_offset_m}")
        check_vehicle_model(self.vehicle_model)
        if self.min_episode_frames < 2:
            raise ValueError(f"min_episode_frames must be >= 2, got {self.min_episode_frames}")


@dataclass
class Episode:
    """One continuous stretch of the log, and what the model did on it."""

    rows: list  #: the log's rows (clonedrive.data.driving_log.LogRow)
    times_s: np.ndarray  #: seconds since the episode's first frame
    offset_m: list[float] = field(default_factory=list)
    heading_rad: list[float] = field(default_factory=list)
    steering: list[float] = field(default_factory=list)
    distance_m: list[float] = field(default_factory=list)
    interventions: list[int] = field(default_factory=list)  #: frame indices

    @property
    def human(self) -> np.ndarray:
        return np.array([row.steering for row in self.rows])


def frame_times(rows: list) -> np.ndarray:
    """Seconds since the first row, from the image names (15 Hz where a name has no time)."""
    from clonedrive.data.driving_log import image_time

    stamps = [image_time(row.center) for row in rows]
    if rows and all(stamp is not None for stamp in stamps):
        return np.array([(stamp - stamps[0]).total_seconds() for stamp in stamps])
    return np.arange(len(rows)) / CONTROL_HZ


def split_episodes(rows: list, times_s: np.ndarray, min_frames: int) -> list[Episode]:
    """Episodes at each timestamp jump (back, or forward by more than the gap); short ones
    dropped."""
    jumps = np.flatnonzero((np.diff(times_s) > SEGMENT_GAP_S) | (np.diff(times_s) <= 0)) + 1
    bounds = [0, *jumps.tolist(), len(rows)]
    return [Episode(rows[start:end], times_s[start:end] - times_s[start])
            for start, end in zip(bounds[:-1], bounds[1:], strict=True)
            if end - start >= min_frames]


def replayable_episodes(log_dir: str | os.PathLike, config: ReplayConfig) -> list[Episode]:
    """The log's episodes, or :class:`ReplayError` naming why it cannot be replayed."""
    from clonedrive.data.driving_log import read_driving_log

    log = read_driving_log(log_dir)
    rows = log.rows
    if len(rows) < 2:
        raise ReplayError(f"{log.csv_path}: {len(rows)} usable rows; nothing to replay")
    speeds = np.array([row.speed_mph for row in rows])
    if not speeds.any():
        raise ReplayError(f"{log.csv_path}: no speed recorded (0 in every row); the replay "
                          "needs the speed to move the car")
    times = frame_times(rows)
    steps = np.clip(np.diff(times), 0.0, SEGMENT_GAP_S)
    distance = float(np.sum(speeds[:-1] * MPH_TO_MPS * steps))
    if distance < config.min_distance_m:
        raise ReplayError(
            f"{log.csv_path}: stationary: the car covers {distance:.1f} m in {len(rows)} rows "
            f"(at most {speeds.max():.3g} mph); at least {config.min_distance_m:g} m needed")
    episodes = split_episodes(rows, times, config.min_episode_frames)
    if not episodes:
        raise ReplayError(
            f"{log.csv_path}: too short: no stretch of at least {config.min_episode_frames} "
            "frames without a jump in the image timestamps")
    return episodes


def frame_images(row) -> dict[str, np.ndarray]:
    """The row's images (RGB) by camera: the centre one, and the side ones it has."""
    from clonedrive.base.images import read_rgb

    images = {"center": read_rgb(row.center)}
    for camera in SIDE_CAMERAS:
        if camera in row.cameras:
            images[camera] = read_rgb(row.image(camera))
    return images


def drive_episode(policy: Any, episode: Episode, rig: Rig, config: ReplayConfig,
                  on_frame: Callable[[np.ndarray, Episode], None] | None = None) -> Episode:
    """Drive ``policy`` (``reset()``, ``act(image, speed_mph) -> (steering, throttle)``) through
    the episode, filling its traces; ``on_frame(view, episode)`` sees each synthesised view."""
    motion = RelativeMotion(config.vehicle_model)
    travelled = 0.0
    policy.reset()
    steps = np.append(np.diff(episode.times_s), 1.0 / CONTROL_HZ)
    for index, row in enumerate(episode.rows):
        view = synthesise(frame_images(row), rig, motion.offset_m, motion.heading_rad)
        steering = float(np.clip(policy.act(view, row.speed_mph)[0], -1.0, 1.0))
        episode.offset_m.append(motion.offset_m)
        episode.heading_rad.append(motion.heading_rad)
        episode.steering.append(steering)
        episode.distance_m.append(travelled)
        if on_frame is not None:
            on_frame(view, episode)
        travelled += motion.advance(steering, row.steering, row.speed_mph, float(steps[index]))
        if abs(motion.offset_m) > config.max_offset_m:
            episode.interventions.append(index)
            motion.put_back()
    return episode


def episode_figures(episode: Episode, config: ReplayConfig) -> dict:
    """Distance, time, interventions, autonomy, offsets and jitter of a driven episode."""
    elapsed = float(episode.times_s[-1]) if len(episode.times_s) > 1 else 0.0
    distance = episode.distance_m[-1] if episode.distance_m else 0.0
    count = len(episode.interventions)
    steering = np.array(episode.steering)
    offsets = np.abs(np.array(episode.offset_m))
    return {
        "first_row": episode.rows[0].row,
        "frames": len(episode.rows),
        "elapsed_s": round(elapsed, 3),
        "distance_m": round(distance, 2),
        "interventions": count,
        "autonomy_pct": autonomy(count, elapsed, config.intervention_penalty_s),
        "interventions_per_km": round(count / (distance / 1000.0), 3) if distance > 0 else None,
        "mean_abs_offset_m": round(float(offsets.mean()), 4),
        "max_abs_offset_m": round(float(offsets.max()), 4),
        "jitter_per_s": jitter(steering, elapsed),
        "human_jitter_per_s": jitter(episode.human, elapsed),
    }


def autonomy(interventions: int, elapsed_s: float, penalty_s: float) -> float | None:
    """PilotNet's autonomy [%], floored at 0; None for no elapsed time."""
    if elapsed_s <= 0:
        return None
    return round(autonomy_pct(interventions, elapsed_s, penalty_s), 2)


def jitter(steering: np.ndarray, elapsed_s: float) -> float | None:
    """Mean |change of steering| per second: the sum of the frame-to-frame changes over the
    elapsed time."""
    if elapsed_s <= 0 or len(steering) < 2:
        return None
    return round(float(np.abs(np.diff(steering)).sum() / elapsed_s), 4)


def log_sources(episodes: list[Episode]) -> list[str]:
    """The cameras every frame of the replay has (``center``, and the sides where all have
    them)."""
    cameras = set(SIDE_CAMERAS)
    for episode in episodes:
        for row in episode.rows:
            cameras &= set(row.cameras)
    return ["center", *sorted(cameras)]


def calibration_frames(episodes: list[Episode], count: int) -> list[dict[str, np.ndarray]]:
    """``count`` three-camera frames spread over the episodes."""
    rows = [row for episode in episodes for row in episode.rows]
    picks = np.linspace(0, len(rows) - 1, count).round().astype(int)
    return [frame_images(rows[pick]) for pick in picks]


def log_path(log_dir: str | os.PathLike) -> Path:
    from clonedrive.data.driving_log import resolve_csv_path

    return resolve_csv_path(log_dir)
