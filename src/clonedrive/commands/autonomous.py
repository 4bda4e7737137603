"""``clonedrive autonomous``: our simulator drives as the Udacity simulator's client."""

from __future__ import annotations

import json
import sys

from clonedrive.udacity_spec import PORT

HELP = "let a drive server (clonedrive drive, or Udacity's drive.py) steer our simulated car"
DESCRIPTION = (
    "Run the simulator headless in autonomous mode: connect to a drive server at "
    "ws://HOST:PORT/socket.io/?EIO=4&transport=websocket and speak exactly as the Udacity "
    "simulator does (telemetry with a base64 JPEG from the center camera, lock-step steer "
    "replies). Start the server first, e.g. `clonedrive drive model.keras`. Prints laps, "
    "interventions, autonomy % and cross-track error at the end."
)


def add_arguments(parser) -> None:
    parser.add_argument("--track", default="lake", help="lake, mountain, gen:<seed> or a .json")
    parser.add_argument("--laps", type=int, default=1, help="laps to drive")
    parser.add_argument("--host", default="127.0.0.1", help="drive server host")
    parser.add_argument("--port", type=int, default=PORT, help="drive server port")
    parser.add_argument("--connect-timeout", type=float, default=30.0, metavar="SECONDS",
                        help="keep retrying to reach the drive server this long (default 30)")
    parser.add_argument("--max-seconds", type=float, default=None,
                        help="stop after this much simulated time (default: generous per lap)")
    parser.add_argument("--no-scenery", action="store_true",
                        help="road and terrain only (no trees, rocks, barriers)")
    parser.add_argument("--json", action="store_true", help="print the metrics as JSON")


def run(args) -> int:
    from clonedrive.udacity.client import (
        AutonomousConfig,
        ClientConfig,
        DriveServerError,
        drive_autonomous,
    )
    from clonedrive.world.catalog import load_track
    from clonedrive.world.track import TrackError

    try:
        load_track(args.track)
    except TrackError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    try:
        config = AutonomousConfig(track=args.track, laps=args.laps, max_seconds=args.max_seconds,
                                  scenery=not args.no_scenery,
                                  client=ClientConfig(host=args.host, port=args.port,
                                                      connect_timeout_s=args.connect_timeout))
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    try:
        summary = drive_autonomous(config, progress=not args.json)
    except DriveServerError as error:
        print(f"error: {error}", file=sys.stderr)
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
