"""Open-loop check of a steering model on a recorded Udacity log: does it steer as the human did?

``crosscheck(policy, LOG_DIR, OUT)`` predicts the steering for every usable centre image of a
``driving_log.csv`` (through :mod:`clonedrive.data.driving_log`, so any real Udacity log reads)
and compares it with the human's, row by row:

- **RMSE** of the prediction against the recorded steering, beside two baselines that need no
  model: always 0 (``rmse_zero``: the straight-ahead guess) and always the log's own mean
  (``rmse_mean``: its standard deviation, the best constant -- it peeks at the answers);
- **correlation** (Pearson) of the prediction with the human's steering *lightly smoothed*: a
  centred moving average over ``smoothing_frames`` frames (5 = a third of a second at 15 Hz).
  Keyboard steering comes in 0 / +-1 spikes that no image explains; the smoothed trace is the
  intent. ``correlation_raw`` is against the recorded values. A constant trace (a car that never
  steers) has no correlation: None.

Rows are split into segments where consecutive image timestamps are more than
:data:`SEGMENT_GAP_S` apart (a log that is several slices, or paused recording); smoothing never
crosses a segment boundary. Writes ``OUT/crosscheck.json``, ``OUT/crosscheck.csv`` (per row:
line, time, human, smoothed, predicted) and ``OUT/crosscheck.png`` (the traces over time and a
scatter of prediction against smoothed human).
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from clonedrive.base.config import write_json_atomic, write_text_atomic
from clonedrive.base.udacity_spec import CONTROL_HZ, IMAGE_SHAPE

#: A gap between consecutive images longer than this starts a new segment [s].
SEGMENT_GAP_S = 0.5
JSON_NAME, CSV_NAME, PLOT_NAME = "crosscheck.json", "crosscheck.csv", "crosscheck.png"


@dataclass(frozen=True)
class CrosscheckConfig:
    """How the check is made."""

    #: centred moving-average window on the human's steering, frames (odd; 1 = no smoothing)
    smoothing_frames: int = 5
    #: at most this many rows are predicted (evenly spaced over the log beyond it)
    max_rows: int = 20_000
    batch_size: int = 64

    def __post_init__(self) -> None:
        if self.smoothing_frames < 1 or self.smoothing_frames % 2 == 0:
            raise ValueError(
                f"smoothing_frames must be an odd number >= 1, got {self.smoothing_frames}")
        if self.max_rows < 2:
            raise ValueError(f"max_rows must be at least 2, got {self.max_rows}")
        if self.batch_size < 1:
            raise ValueError(f"batch_size must be at least 1, got {self.batch_size}")


def smooth(values: np.ndarray, window: int, segments: np.ndarray) -> np.ndarray:
    """Centred moving average of ``values`` over ``window`` samples, within each segment (the
    window shrinks at a segment's ends instead of running into the next one)."""
    values = np.asarray(values, dtype=np.float64)
    out = np.empty_like(values)
    half = window // 2
    for segment in np.unique(segments):
        index = np.flatnonzero(segments == segment)
        part = values[index]
        sums = np.concatenate([[0.0], np.cumsum(part)])
        starts = np.clip(np.arange(len(part)) - half, 0, len(part))
        ends = np.clip(np.arange(len(part)) + half + 1, 0, len(part))
        out[index] = (sums[ends] - sums[starts]) / (ends - starts)
    return out


def correlation(a: np.ndarray, b: np.ndarray) -> float | None:
    """Pearson correlation, or None when either series is constant or too short."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if len(a) < 3 or np.std(a) < 1e-9 or np.std(b) < 1e-9:
        return None
    return float(np.corrcoef(a, b)[0, 1])


def rmse(a: np.ndarray, b: np.ndarray | float) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))


def _times_and_segments(rows: list) -> tuple[np.ndarray, np.ndarray]:
    """Seconds since the first row (from image names, else 15 Hz) and a segment id per row."""
    from clonedrive.data.driving_log import image_time

    stamps = [image_time(row.center) for row in rows]
    if all(stamp is not None for stamp in stamps) and len(rows) > 0:
        first = stamps[0]
        times = np.array([(stamp - first).total_seconds() for stamp in stamps])
    else:
        times = np.arange(len(rows)) / CONTROL_HZ
    gaps = np.abs(np.diff(times)) > SEGMENT_GAP_S
    return times, np.concatenate([[0], np.cumsum(gaps)]).astype(np.int64)


def crosscheck(policy: Any, log_dir: str | os.PathLike, out_dir: str | os.PathLike,
               config: CrosscheckConfig | None = None, *, model_path: str | None = None,
               progress: bool = False) -> dict:
    """Run the check (see the module doc); returns ``crosscheck.json``'s content.

    ``policy``: anything with ``predict_steering(frames (N, 160, 320, 3) uint8) -> (N,)``
    (a :class:`~clonedrive.drivers.policy.NetworkPolicy`). Raises ``FileNotFoundError`` (no
    log) or ``ValueError`` (a log with fewer than 2 usable centre images).
    """
    from clonedrive.base.images import ImageDecodeError, read_rgb
    from clonedrive.data.driving_log import read_driving_log

    config = config or CrosscheckConfig()
    log = read_driving_log(log_dir, verify_images="exists")
    rows = list(log.rows)
    if len(rows) > config.max_rows:
        picks = np.linspace(0, len(rows) - 1, config.max_rows).round().astype(int)
        rows = [rows[int(index)] for index in picks]
    images, used, unreadable = [], [], []
    iterable = rows
    if progress:
        from clonedrive.base.progress import progress_bar

        iterable = progress_bar(rows, desc="reading centre images", unit="row", leave=False)
    predicted_parts = []
    nan_before = _nan_count(policy)
    for row in iterable:
        try:
            images.append(read_rgb(row.center, shape=IMAGE_SHAPE))
            used.append(row)
        except ImageDecodeError as error:
            unreadable.append(f"line {row.row}: {error}")
        if len(images) == config.batch_size:
            predicted_parts.append(policy.predict_steering(np.stack(images)))
            images = []
    if images:
        predicted_parts.append(policy.predict_steering(np.stack(images)))
    if len(used) < 2:
        raise ValueError(f"{log.csv_path}: {len(used)} usable centre image(s); the crosscheck "
                         "needs at least 2")
    predicted = np.concatenate(predicted_parts).astype(np.float64)
    nan_predictions = _nan_count(policy) - nan_before
    human = np.array([row.steering for row in used], dtype=np.float64)
    times, segments = _times_and_segments(used)
    smoothed = smooth(human, config.smoothing_frames, segments)

    figures = {
        "rows": len(used),
        "rmse": rmse(predicted, human),
        "rmse_zero": rmse(0.0, human),
        "rmse_mean": rmse(float(np.mean(human)), human),
        "rmse_vs_smoothed": rmse(predicted, smoothed),
        "correlation": correlation(predicted, smoothed),
        "correlation_raw": correlation(predicted, human),
        "human_mean": float(np.mean(human)),
        "human_std": float(np.std(human)),
        "human_zero_fraction": float(np.mean(human == 0.0)),
        "predicted_mean": float(np.mean(predicted)),
        "predicted_std": float(np.std(predicted)),
    }
    figures = {key: (round(value, 5) if isinstance(value, float) else value)
               for key, value in figures.items()}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = {
        "model": model_path,
        "log": str(log.csv_path),
        "config": asdict(config),
        "rows_in_log": log.total_rows,
        "rows_skipped_by_reader": len(log.skipped),
        "rows_unreadable_image": len(unreadable),
        "nan_predictions": nan_predictions,
        "unreadable": unreadable[:20],
        "segments": int(segments.max()) + 1,
        "seconds": round(sum(float(np.ptp(times[segments == segment]))
                             for segment in np.unique(segments)), 3),
        **figures,
        "files": {"json": JSON_NAME, "csv": CSV_NAME, "plot": PLOT_NAME},
    }
    _write_rows(out / CSV_NAME, used, times, human, smoothed, predicted)
    plot_crosscheck(out / PLOT_NAME, times, segments, human, smoothed, predicted, report)
    write_json_atomic(out / JSON_NAME, report)
    return report


def _nan_count(policy: Any) -> int:
    """The NaN or infinite steering predictions ``policy`` counted so far (a
    :class:`~clonedrive.drivers.policy.NetworkPolicy` counts them, and steers 0 instead)."""
    return int(getattr(policy, "nan_predictions", 0) or 0)


def _write_rows(path: Path, rows: list, times, human, smoothed, predicted) -> None:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["line", "time_s", "human", "human_smoothed", "predicted"])
    for row, *values in zip(rows, times, human, smoothed, predicted, strict=True):
        writer.writerow([row.row, *(f"{value:.5f}" for value in values)])
    write_text_atomic(path, buffer.getvalue())


def _label(value: float | None) -> str:
    return "n/a" if value is None or (isinstance(value, float) and math.isnan(value)) else (
        f"{value:.2f}")


def plot_crosscheck(path: Path, times, segments, human, smoothed, predicted,
                    report: dict) -> Path:
    """The traces over time (segments side by side, gaps cut out) and a scatter."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    # Cut the gaps between segments out of the time axis.
    axis = np.empty_like(times)
    offset = 0.0
    for segment in np.unique(segments):
        index = np.flatnonzero(segments == segment)
        axis[index] = times[index] - times[index[0]] + offset
        offset = axis[index[-1]] + 1.0 / CONTROL_HZ
    figure, (trace, scatter) = plt.subplots(
        1, 2, figsize=(12, 3.8), gridspec_kw={"width_ratios": [3, 1]})
    # A NaN after each segment's last point, so that no line joins two segments.
    breaks = np.flatnonzero(np.diff(segments)) + 1
    for values, style in ((human, {"color": "0.7", "linewidth": 0.8, "label": "human (recorded)"}),
                          (smoothed, {"color": "black", "linewidth": 1.4,
                                      "label": "human, smoothed"}),
                          (predicted, {"color": "tab:red", "linewidth": 1.2, "label": "model"})):
        trace.plot(np.insert(axis, breaks, np.nan), np.insert(values, breaks, np.nan), **style)
    for segment in np.unique(segments)[1:]:
        trace.axvline(axis[np.flatnonzero(segments == segment)[0]], color="0.5",
                      linestyle=":", linewidth=0.8)
    trace.set_xlabel("time in the log [s] (dotted: a gap in the log)")
    trace.set_ylabel("steering [-1, 1]")
    trace.set_ylim(-1.05, 1.05)
    trace.legend(loc="upper right", fontsize=8)
    trace.set_title(
        f"{Path(report['log']).parent.name}: RMSE {report['rmse']:.3f} (always 0: "
        f"{report['rmse_zero']:.3f}, always the mean: {report['rmse_mean']:.3f}), "
        f"r = {_label(report['correlation'])} with the smoothed human", fontsize=10)
    scatter.scatter(smoothed, predicted, s=6, color="tab:red", alpha=0.5)
    scatter.plot([-1, 1], [-1, 1], color="0.5", linewidth=0.8)
    scatter.set_xlim(-1.05, 1.05)
    scatter.set_ylim(-1.05, 1.05)
    scatter.set_xlabel("human, smoothed")
    scatter.set_ylabel("model")
    scatter.set_aspect("equal")
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110)
    plt.close(figure)
    from clonedrive.base.config import write_bytes_atomic

    write_bytes_atomic(path, buffer.getvalue())
    return path


def format_summary(report: dict) -> str:
    """A few lines for a person."""
    return "\n".join([
        f"{report['log']}: {report['rows']} rows ({report['rows_skipped_by_reader']} skipped by "
        f"the reader, {report['rows_unreadable_image']} unreadable images), "
        f"{report['segments']} segment(s), {report['seconds']:.1f} s",
        f"  RMSE          {report['rmse']:.4f}   (always 0: {report['rmse_zero']:.4f}, always "
        f"the mean: {report['rmse_mean']:.4f})",
        f"  correlation   {_label(report['correlation'])} with the human smoothed over "
        f"{report['config']['smoothing_frames']} frames ({_label(report['correlation_raw'])} "
        "with the recorded values)",
        f"  human steering mean {report['human_mean']:+.3f} std {report['human_std']:.3f} "
        f"({100 * report['human_zero_fraction']:.0f}% exactly 0); model mean "
        f"{report['predicted_mean']:+.3f} std {report['predicted_std']:.3f}",
    ] + ([f"  {report['nan_predictions']} prediction(s) were NaN or infinite: counted as "
          "steering 0 in the figures above"] if report.get("nan_predictions") else []))
