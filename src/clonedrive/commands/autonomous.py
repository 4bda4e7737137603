"""``clonedrive autonomous``: our simulator drives as the Udacity simulator's client."""

from __future__ import annotations

import json
import sys

from clonedrive.commands.counts import MAX_LAPS, count, speed_flag_error
from clonedrive.commands.render_options import add_render_arguments, renderer_error
from clonedrive.world.names import TRACK_NAMES_HELP

HELP = "let a drive server (clonedrive drive, or Udacity's drive.py) steer our simulated car"
DESCRIPTION = (
    "Run the simulator headless in autonomous mode: connect to a drive server at "
    "ws://HOST:PORT/socket.io/?EIO=4&transport=websocket and speak exactly as the Udacity "
    "simulator does (telemetry with a base64 JPEG from the center camera, lock-step steer "
    "replies). Start the server first, e.g. `clonedrive drive model.keras`. Prints laps, "
    "interventions, autonomy % and cross-track error at the end."
)
#: Example command lines, shown at the end of ``clonedrive autonomous --help``.
EXAMPLES = (
    "clonedrive drive runs/x/model.keras &   # in one shell",
    "clonedrive autonomous --track lake --laps 1",
)


def add_arguments(parser) -> None:
    from clonedrive.udacity.client import AutonomousConfig

    d = AutonomousConfig()
    parser.add_argument("--track", default=d.track, help=TRACK_NAMES_HELP)
    parser.add_argument("--laps", type=count(MAX_LAPS), default=d.laps, help="laps to drive")
    parser.add_argument("--speed", type=float, default=d.speed_mph, metavar="MPH",
                        help="the drive server's set speed (drive.py's and `clonedrive drive`'s "
                             "default): interventions put the car back at it and the time "
                             "limit follows from it")
    parser.add_argument("--host", default=d.client.host, help="drive server host")
    parser.add_argument("--port", type=int, default=d.client.port, help="drive server port")
    parser.add_argument("--connect-timeout", type=float, default=d.client.connect_timeout_s,
                        metavar="SECONDS",
                        help="keep retrying to reach the drive server this long")
    parser.add_argument("--max-seconds", type=float, default=d.max_seconds,
                        help="stop after this much simulated time (default: the time limit, "
                             "2.5 x the laps' time at --speed + 30 s)")
    parser.add_argument("--seed", type=int, default=d.seed, help="the scene's seed")
    parser.add_argument("--no-scenery", action="store_true",
                        help="road and terrain only (no trees, rocks, barriers)")
    add_render_arguments(parser, crop=False)
    parser.add_argument("--json", action="store_true", help="print the metrics as JSON")


def run(args) -> int:
    speed_problem = speed_flag_error(args, "--speed")
    if speed_problem:  # named as the flag the user typed, before anything loads
        print(f"clonedrive autonomous: {speed_problem}", file=sys.stderr)
        return 2
    from clonedrive.udacity.client import (
        AutonomousConfig,
        ClientConfig,
        DriveServerError,
        drive_autonomous,
    )
    from clonedrive.world.catalog import load_track
    from clonedrive.world.track import TrackError

    problem = renderer_error(args, "autonomous")
    if problem:
        print(problem, file=sys.stderr)
        return 2
    try:
        load_track(args.track)
    except TrackError as error:
        print(f"clonedrive autonomous: {error}", file=sys.stderr)
        return 2
    try:
        config = AutonomousConfig(track=args.track, laps=args.laps, speed_mph=args.speed,
                                  max_seconds=args.max_seconds, scenery=not args.no_scenery,
                                  seed=args.seed, renderer=args.renderer,
                                  client=ClientConfig(host=args.host, port=args.port,
                                                      connect_timeout_s=args.connect_timeout))
    except ValueError as error:
        print(f"clonedrive autonomous: {error}", file=sys.stderr)
        return 2
    try:
        summary = drive_autonomous(config, progress=not args.json)
    except DriveServerError as error:
        print(f"clonedrive autonomous: {error}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"{summary['track']}: {summary['laps_completed']}/{summary['laps_target']} laps, "
          f"{summary['interventions']} interventions, autonomy {summary['autonomy_pct']:.1f} %, "
          f"mean |CTE| {summary['mean_abs_cte_m']:.2f} m, max |CTE| "
          f"{summary['max_abs_cte_m']:.2f} m, mean speed {summary['mean_speed_mph']:.1f} mph, "
          f"{summary['distance_m']:.0f} m in {summary['elapsed_s']:.0f} s")
    return 0
