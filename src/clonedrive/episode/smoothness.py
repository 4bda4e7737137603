"""How smoothly a car was driven, as numbers: steering rate and jerk, lateral acceleration and
its jerk, per run, and each against the expert's on the same track (DESIGN.md: smoothness ratio).

The seed's car drove "quite nervous": these figures say how nervous. From one run's per-step
arrays at the control rate (``dt = 1 / control_hz``):

- **steering rate** [1/s]: mean ``|d steering / dt|``, steering in [-1, 1] (the figure eval.json
  has always called ``smoothness``);
- **steering jerk** [1/s^2]: mean ``|d^2 steering / dt^2|``, how abruptly the hand moves;
- **lateral acceleration** [m/s^2]: ``v * d(course)/dt`` from the driven path (the course is the
  direction of travel between successive positions), as RMS and maximum;
- **lateral jerk** [m/s^3]: mean ``|d a_lat / dt|``.

Differences never span an intervention (the car is put back on the road: a jump, not driving),
nor steps slower than :data:`MIN_SPEED_MPS` for the lateral figures (a course needs motion).
:func:`smoothness_ratios` divides a run's figures by the expert's reference run on the same
track and speed cap (lower is smoother; 1.0 = as smooth as the expert).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: Below this speed [m/s] the direction of travel is not measured (lateral figures skip it).
MIN_SPEED_MPS = 1.0
#: Significant digits each figure keeps: a gentle track's steering rate is about 0.005 /s, which
#: four decimals would cut to two digits, and its ratio to the expert's by up to 1-2 %.
FIGURE_DIGITS = 6
#: The figures of :func:`smoothness_figures`, in order.
FIGURES = ("steering_rate_per_s", "steering_jerk_per_s2", "lateral_accel_rms_mps2",
           "lateral_accel_max_mps2", "lateral_jerk_mps3")


def round_figure(value: float) -> float:
    """``value`` to :data:`FIGURE_DIGITS` significant digits (as every figure here is kept)."""
    value = float(value)
    if value == 0.0 or not math.isfinite(value):
        return value
    return round(value, FIGURE_DIGITS - 1 - math.floor(math.log10(abs(value))))


def _segments(count: int, breaks: Sequence[int]) -> list[slice]:
    """Index ranges between the steps after which the car was put back (``breaks``)."""
    edges = sorted({int(b) + 1 for b in breaks if 0 <= int(b) < count - 1})
    starts = [0, *edges]
    ends = [*edges, count]
    return [slice(start, end) for start, end in zip(starts, ends, strict=True) if end > start]


def _mean_abs(parts: list[np.ndarray]) -> float:
    values = np.concatenate(parts) if parts else np.zeros(0)
    return float(np.mean(np.abs(values))) if len(values) else 0.0


def smoothness_figures(steering: Sequence[float], x_m: Sequence[float], y_m: Sequence[float],
                       speed_mps: Sequence[float], control_hz: float,
                       breaks: Sequence[int] = ()) -> dict[str, float]:
    """The figures of :data:`FIGURES` for one run; ``breaks``: indices of the steps after
    which the car was put back on the road (no difference spans them)."""
    steering = np.asarray(steering, dtype=float)
    x, y = np.asarray(x_m, dtype=float), np.asarray(y_m, dtype=float)
    speed = np.asarray(speed_mps, dtype=float)
    if not (len(steering) == len(x) == len(y) == len(speed)):
        raise ValueError("steering, x, y and speed must have one value per step")
    if not control_hz > 0:
        raise ValueError(f"control_hz must be positive, got {control_hz}")
    dt = 1.0 / control_hz
    rates, jerks, lateral, lateral_jerks = [], [], [], []
    for part in _segments(len(steering), breaks):
        s = steering[part]
        rates.append(np.diff(s) / dt)
        jerks.append(np.diff(s, n=2) / dt**2)
        dx, dy = np.diff(x[part]), np.diff(y[part])
        moving = np.hypot(dx, dy) >= MIN_SPEED_MPS * dt
        course = np.arctan2(dy, dx)
        turn = (np.diff(course) + math.pi) % (2.0 * math.pi) - math.pi  # wrapped, per step
        both = moving[1:] & moving[:-1]
        v = 0.5 * (speed[part][1:-1] + speed[part][2:]) if len(turn) else np.zeros(0)
        a_lat = np.where(both, v * turn / dt, np.nan)
        lateral.append(a_lat[both])
        step = np.diff(a_lat) / dt
        lateral_jerks.append(step[np.isfinite(step)])
    a = np.concatenate(lateral) if lateral else np.zeros(0)
    figures = {
        "steering_rate_per_s": _mean_abs(rates),
        "steering_jerk_per_s2": _mean_abs(jerks),
        "lateral_accel_rms_mps2": float(np.sqrt(np.mean(a * a))) if len(a) else 0.0,
        "lateral_accel_max_mps2": float(np.max(np.abs(a))) if len(a) else 0.0,
        "lateral_jerk_mps3": _mean_abs(lateral_jerks),
    }
    return {name: round_figure(value) for name, value in figures.items()}


def smoothness_ratios(run: dict, expert: dict) -> dict[str, float | None]:
    """``<figure>_ratio``: each of the run's :data:`FIGURES` over the expert's (None where the
    expert's is 0); both dicts hold the figures, e.g. two runs' eval.json entries."""
    ratios: dict[str, float | None] = {}
    for name in FIGURES:
        mine, theirs = run.get(name), expert.get(name)
        ratios[f"{name}_ratio"] = (round(float(mine) / float(theirs), 4)
                                   if mine is not None and theirs else None)
    return ratios
