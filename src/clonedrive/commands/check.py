"""``clonedrive check DATA_DIR``: read a Udacity-format log and report what is usable."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass

HELP = "check a Udacity-format driving log: usable rows, skipped rows and why, steering histogram"
DESCRIPTION = (
    "Read DATA_DIR/driving_log.csv (any Udacity-format log: simulator-written or the sample data "
    "set, POSIX or Windows paths, header or none) and report rows, usable rows, rows skipped "
    "grouped by reason with their line numbers, a steering histogram, the mean speed and the "
    "recording's duration. Rows whose left/right images are missing (center-only data sets) stay "
    "usable for the cameras they have, and are counted; image files that more than one row "
    "names (two recorders in one folder) are reported. Every image is decoded unless "
    "--no-decode is given. Exit status 0 when the log is readable (even with skipped rows), 1 "
    "when the CSV is missing or is not a driving log (UTF-16, an image, binary data)."
)
#: Example command lines, shown at the end of ``clonedrive check --help``.
EXAMPLES = (
    "clonedrive check data/middle",
    "clonedrive check ~/udacity/my_recording --json",
)

BAR_WIDTH = 40
ROWS_SHOWN = 5


@dataclass(frozen=True)
class CheckConfig:
    """What ``clonedrive check`` verifies of a log's images."""

    decode: bool = True  #: decode every image (False: only check that the files exist)

    def __post_init__(self) -> None:
        if not isinstance(self.decode, bool):
            raise ValueError(f"decode must be true or false, got {self.decode!r}")

    @property
    def verify_images(self) -> str:
        """The :func:`~clonedrive.data.driving_log.read_driving_log` mode this asks for."""
        return "decode" if self.decode else "exists"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = CheckConfig()
    parser.add_argument("data_dir", metavar="DATA_DIR", help="folder with driving_log.csv and IMG/")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument(
        "--no-decode",
        dest="decode",
        action="store_false",
        default=defaults.decode,
        help="only check that images exist (faster); by default every image is decoded",
    )


def run(args: argparse.Namespace) -> int:
    from clonedrive.data.driving_log import DrivingLogError, read_driving_log

    config = CheckConfig(decode=args.decode)
    try:
        log = read_driving_log(
            args.data_dir,
            verify_images=config.verify_images,
            progress=not args.json and sys.stderr.isatty(),
        )
    except (FileNotFoundError, DrivingLogError) as error:
        print(f"clonedrive check: {error}", file=sys.stderr)
        return 1
    summary = summarize(log)
    if args.json:
        print(json.dumps(summary))
    else:
        print(format_summary(log, summary))
    for warning in log.warnings:
        print(f"clonedrive check: warning: {warning}", file=sys.stderr)
    return 0


def summarize(log) -> dict:
    """The figures ``check --json`` prints, from a read :class:`DrivingLog`."""
    import numpy as np

    from clonedrive.data.driving_log import STEERING_HISTOGRAM_BINS, image_time

    groups = log.skipped_by_reason()
    shared = log.shared_images()
    steering = np.array([row.steering for row in log.rows], dtype=np.float64)
    speed = np.array([row.speed_mph for row in log.rows], dtype=np.float64)
    counts, edges = np.histogram(steering, bins=STEERING_HISTOGRAM_BINS, range=(-1.0, 1.0))
    times = [image_time(row.center) for row in log.rows]
    times = [moment for moment in times if moment is not None]
    duration_s = (max(times) - min(times)).total_seconds() if times else None
    has_rows = steering.size > 0
    return {
        "csv": str(log.csv_path),
        "has_header": log.has_header,
        "rows": log.total_rows,
        "usable_rows": len(log.rows),
        "skipped": {reason: len(items) for reason, items in groups.items()},
        "skipped_rows": {reason: [item.row for item in items] for reason, items in groups.items()},
        "images_missing": len(groups.get("image_missing", [])),
        "images_corrupt": len(groups.get("image_corrupt", [])),
        "side_images_missing": log.side_images_missing,
        "shared_images": len(shared),
        "rows_sharing_images": sorted({row for rows in shared.values() for row in rows}),
        "steering_mean": float(steering.mean()) if has_rows else None,
        "steering_std": float(steering.std()) if has_rows else None,
        "steering_min": float(steering.min()) if has_rows else None,
        "steering_max": float(steering.max()) if has_rows else None,
        "steering_zero_fraction": float(np.mean(steering == 0.0)) if has_rows else None,
        "steering_histogram": {
            "edges": [float(edge) for edge in edges],
            "counts": [int(count) for count in counts],
        },
        "speed_mean_mph": float(speed.mean()) if has_rows else None,
        "duration_s": duration_s,
        "warnings": list(log.warnings),
    }


def format_summary(log, summary: dict) -> str:
    """The human-readable report."""
    header = "header" if summary["has_header"] else "no header"
    lines = [
        f"driving log: {summary['csv']} ({header})",
        f"rows: {summary['rows']}   usable: {summary['usable_rows']}   "
        f"skipped: {summary['rows'] - summary['usable_rows']}",
    ]
    if summary["side_images_missing"]:
        lines.append(f"  of the usable rows, {summary['side_images_missing']} have no left and/or "
                     "right image (a center-only data set?): they are used for the cameras they "
                     "have")
    if summary["shared_images"]:
        rows = summary["rows_sharing_images"]
        numbers = ", ".join(str(row) for row in rows[:ROWS_SHOWN])
        more = f" and {len(rows) - ROWS_SHOWN} more" if len(rows) > ROWS_SHOWN else ""
        lines.append(f"image files named by more than one row: {summary['shared_images']} "
                     f"(lines {numbers}{more}); two recorders wrote into one folder?")
    groups = log.skipped_by_reason()
    if groups:
        lines.append("skipped rows by reason:")
        for reason, items in groups.items():
            numbers = ", ".join(str(item.row) for item in items[:ROWS_SHOWN])
            more = f" and {len(items) - ROWS_SHOWN} more" if len(items) > ROWS_SHOWN else ""
            lines.append(f"  {reason}: {len(items)} (lines {numbers}{more})")
            lines.append(f"    e.g. {items[0].detail}")
    if summary["usable_rows"]:
        lines.append("steering histogram (usable rows):")
        counts = summary["steering_histogram"]["counts"]
        edges = summary["steering_histogram"]["edges"]
        peak = max(counts)
        for index, count in enumerate(counts):
            low, high = edges[index], edges[index + 1]
            closing = "]" if index == len(counts) - 1 else ")"
            bar = "#" * (round(BAR_WIDTH * count / peak) if peak else 0)
            if count and not bar:
                bar = "#"
            lines.append(f"  [{low:+.2f}, {high:+.2f}{closing} {bar:<{BAR_WIDTH}} {count}")
        lines.append(
            f"steering: mean {summary['steering_mean']:+.4f}  std {summary['steering_std']:.4f}  "
            f"min {summary['steering_min']:+.3f}  max {summary['steering_max']:+.3f}  "
            f"exactly 0: {100 * summary['steering_zero_fraction']:.0f}%"
        )
        lines.append(f"speed: mean {summary['speed_mean_mph']:.2f} mph")
    if summary["duration_s"] is not None:
        lines.append(
            f"duration: {summary['duration_s']:.1f} s (first to last center image timestamp)"
        )
    return "\n".join(lines)
