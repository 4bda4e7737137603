"""``clonedrive record``: let the expert drive and record a Udacity-format log."""

from __future__ import annotations

import argparse
import json
import sys

from clonedrive.commands.counts import MAX_LAPS, MAX_OFF_ROAD_EVENTS, count, speed_flag_error
from clonedrive.commands.render_options import add_render_arguments, renderer_error
from clonedrive.world.names import TRACK_NAMES_HELP

HELP = "record the expert driving a track as a Udacity-format log (driving_log.csv + IMG/)"
DESCRIPTION = (
    "Drive the expert autopilot around a track in the headless simulator and write OUT/"
    "driving_log.csv and OUT/IMG/ exactly as the Udacity simulator records (one row per 1/15 s "
    "step, 320x160 JPEGs from the center, left and right cameras, image names timestamped in "
    "simulated time), plus OUT/config.json. Styles: center, left/right (a line toward that "
    "edge), weave (slow swerves between the edges: recovery data), turns (only the rows in "
    "curves). --noise perturbs the steering the car applies while the recorded label stays the "
    "expert's clean command. An existing OUT is appended to, with timestamps continuing after "
    "its last image. A killed recorder leaves a log whose every row's images exist."
)
#: Example command lines, shown at the end of ``clonedrive record --help``.
EXAMPLES = (
    "clonedrive record --track lake --style center --laps 2 --speed 30 --out data/middle",
    "clonedrive record --track mountain --style weave --laps 1 --out data/weave",
)

HISTOGRAM_BAR_WIDTH = 40


def add_log_format_arguments(parser: argparse.ArgumentParser) -> None:
    """How a recording is written: shared by ``record`` and the ``sim`` window."""
    from clonedrive.data.recorder import RecordConfig

    d = RecordConfig()
    parser.add_argument("--header", action="store_true",
                        help="write the CSV header line (the Udacity simulator writes none)")
    parser.add_argument("--relative-paths", action="store_true",
                        help="write IMG/<name> instead of absolute image paths")
    parser.add_argument("--jpeg-quality", type=int, default=d.jpeg_quality,
                        help="JPEG quality 1-100")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from clonedrive.data.recorder import RecordConfig
    from clonedrive.drivers.expert import STYLES

    d = RecordConfig()
    parser.add_argument("--track", default=d.track,
                        help=TRACK_NAMES_HELP)
    parser.add_argument("--style", default=d.style, choices=STYLES, help="how the expert drives")
    parser.add_argument("--laps", type=count(MAX_LAPS), default=d.laps, help="laps to drive")
    parser.add_argument("--seconds", type=float, default=d.seconds,
                        help="stop after this many seconds of simulated driving")
    parser.add_argument("--speed", type=float, default=d.speed_mph,
                        help="set speed in mph (a maximum: the expert slows for curves)")
    parser.add_argument("--out", required=True, help="folder to write (appended to if it exists)")
    parser.add_argument("--reverse", action="store_true", help="drive the track backwards")
    parser.add_argument("--noise", type=float, default=d.noise,
                        help="std of steering noise applied to the car (labels stay clean)")
    parser.add_argument("--seed", type=int, default=d.seed, help="seeds the noise, weave and scene")
    parser.add_argument("--offset-fraction", type=float, default=d.offset_fraction,
                        help="left/right styles: fraction of the usable half-width off centre")
    parser.add_argument("--max-off-road", type=count(MAX_OFF_ROAD_EVENTS),
                        default=d.max_off_road_events, metavar="N",
                        help="stop early once the expert has left the road N times")
    add_log_format_arguments(parser)
    parser.add_argument("--start-time", default=d.start_time,
                        help="ISO time of the first image name (default: now, local time)")
    parser.add_argument("--no-scenery", action="store_true",
                        help="road and terrain only (no trees, rocks...)")
    looks = parser.add_mutually_exclusive_group()
    looks.add_argument("--look", default=None, metavar="LOOK",
                       help="record in a look drawn from --seed: udacity (towards the Udacity "
                            "simulator's frames: road shade, line colour and wear, light, "
                            "shadows, JPEG), randomized (domain randomisation of light, fog, "
                            "colours, camera height, noise), or clear (default: the theme's)")
    looks.add_argument("--randomize", action="store_true",
                       help="the same as --look randomized")
    add_render_arguments(parser, crop=False)
    parser.add_argument("--json", action="store_true", help="print the summary as one JSON object")


def run(args: argparse.Namespace) -> int:
    speed_problem = speed_flag_error(args, "--speed")
    if speed_problem:  # named as the flag the user typed, before anything loads
        print(f"clonedrive record: {speed_problem}", file=sys.stderr)
        return 2
    from clonedrive.data.log_folder import RecordingFolderError
    from clonedrive.data.recorder import RecordConfig, record
    from clonedrive.data.row_sink import RecordingWriteError
    from clonedrive.sim.conditions import RANDOMIZED_LOOK
    from clonedrive.world.track import TrackError

    problem = renderer_error(args, "record")
    if problem:
        print(problem, file=sys.stderr)
        return 2
    try:
        config = RecordConfig(
            track=args.track, style=args.style, laps=args.laps, seconds=args.seconds,
            speed_mph=args.speed,
            reverse=args.reverse, noise=args.noise, seed=args.seed,
            offset_fraction=args.offset_fraction, max_off_road_events=args.max_off_road,
            header=args.header,
            relative_paths=args.relative_paths, jpeg_quality=args.jpeg_quality,
            start_time=args.start_time, scenery=not args.no_scenery,
            look=RANDOMIZED_LOOK if args.randomize else args.look, renderer=args.renderer,
        )
        summary = record(config, args.out, progress=not args.json and sys.stderr.isatty())
    except (ValueError, TrackError) as error:
        print(f"clonedrive record: {error}", file=sys.stderr)
        return 2
    except (RecordingWriteError, RecordingFolderError) as error:  # a full disk: rows are whole
        print(f"clonedrive record: {error}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(summary.to_dict()))
    else:
        print(format_summary(summary))
    return {"laps": 0, "seconds": 0, "interrupted": 130}.get(summary.stopped, 1)


def format_summary(summary) -> str:
    """The human-readable report."""
    lines = [
        f"{summary.message}: {summary.out_dir}",
        f"rows: {summary.rows} written"
        + (f" ({summary.total_rows} in the log, appended)" if summary.appended else "")
        + (f", {summary.skipped_samples} steps not recorded (outside turns)"
           if summary.skipped_samples else ""),
        f"laps: {summary.laps} ({summary.clean_laps} clean)   off-road events: "
        f"{summary.off_road_events}   distance: {summary.distance_m:.0f} m",
        f"time: {summary.sim_seconds:.1f} s driven in {summary.wall_seconds:.1f} s "
        f"({summary.samples_per_s:.0f} samples/s) after {summary.setup_seconds:.1f} s of "
        "scene setup",
    ]
    counts = summary.steering_histogram.get("counts", [])
    edges = summary.steering_histogram.get("edges", [])
    if counts and sum(counts):
        lines.append("steering histogram (labels):")
        peak = max(counts)
        for index, count in enumerate(counts):
            closing = "]" if index == len(counts) - 1 else ")"
            bar = "#" * round(HISTOGRAM_BAR_WIDTH * count / peak)
            if count and not bar:
                bar = "#"
            lines.append(f"  [{edges[index]:+.2f}, {edges[index + 1]:+.2f}{closing} "
                         f"{bar:<{HISTOGRAM_BAR_WIDTH}} {count}")
    if summary.first_image:
        lines.append(f"images: {summary.first_image} .. {summary.last_image}")
    return "\n".join(lines)
