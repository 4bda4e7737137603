"""``clonedrive sim``: drive the simulator yourself, and record it, in a window."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict

from clonedrive.base.udacity_spec import PORT
from clonedrive.commands.counts import MAX_STEPS, count
from clonedrive.commands.record import add_log_format_arguments
from clonedrive.world.names import TRACK_NAMES_HELP

HELP = "drive a track yourself in a window (keyboard, mouse or gamepad) and record it"
DESCRIPTION = (
    "A window like the Udacity simulator's training mode: choose a track (lake, mountain, a "
    "generated one) and a direction, drive with the keyboard (W/S or arrows: throttle/brake, "
    "A/D or arrows: steering that ramps smoothly, not +-1 spikes), the mouse (M: steering "
    "follows the pointer's horizontal position) or a gamepad (left stick, triggers). R starts "
    "and stops recording into OUT in the Udacity format (driving_log.csv + IMG/, appended to an "
    "existing log); P hands the car to a drive server (`clonedrive drive MODEL` or drive.py) "
    "as the Udacity simulator's autonomous mode does, a held key takes over; Backspace puts the "
    "car back on the road; Esc returns to the menu, and quits from it. Uses OpenGL where a "
    "display exists. Without a display, --offscreen (implied by --screenshot or --steps) "
    "drives --steps steps with the software renderer in an offscreen buffer and can save a "
    "screenshot: e.g. --track lake --hold w --steps 45 --screenshot shot.png."
)
#: Example command lines, shown at the end of ``clonedrive sim --help``.
EXAMPLES = (
    "clonedrive sim --track mountain --out data/by-hand   # drive with the keys, R records",
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from clonedrive.manual.config import DEFAULT_OUT_DIR, ManualConfig

    d = ManualConfig()
    parser.add_argument("--track", default=None,
                        help=f"skip the menu and drive this track: {TRACK_NAMES_HELP}")
    parser.add_argument("--reverse", action="store_true", help="with --track: drive backwards")
    parser.add_argument("--out", default=DEFAULT_OUT_DIR,
                        help="folder R records into (appended to if it holds a log)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--windowed", action="store_true",
                       help="open a window (default when a display exists)")
    where.add_argument("--offscreen", action="store_true",
                       help="no window: software rendering into an offscreen buffer")
    parser.add_argument("--software", action="store_true",
                        help="draw the window with the software renderer (no OpenGL)")
    parser.add_argument("--screenshot", metavar="PATH", default=None,
                        help="after --steps steps, save the window's image (PNG/JPEG) and exit")
    parser.add_argument("--steps", type=count(MAX_STEPS), default=None,
                        help="drive this many 1/15 s steps, then exit (default with "
                             "--screenshot or --offscreen: 30)")
    parser.add_argument("--hold", default="",
                        help="keys held from the start, comma-separated Panda3D names "
                             "(w, arrow_left, ...): for scripted runs")
    parser.add_argument("--record", action="store_true", help="start recording at once")
    parser.add_argument("--server", default=f"{d.server_host}:{d.server_port}",
                        help="HOST:PORT of the drive server autonomous mode (P) connects to")
    parser.add_argument("--seed", type=int, default=d.seed, help="the scene's seed")
    parser.add_argument("--generated-seed", type=int, default=d.generated_seed,
                        help="seed of the menu's generated track (G picks the next)")
    parser.add_argument("--no-scenery", action="store_true",
                        help="road and terrain only (no trees, rocks...): quicker to load")
    add_log_format_arguments(parser)  # the same options as `clonedrive record`
    parser.add_argument("--json", action="store_true",
                        help="print a summary of the run as one JSON object")


NO_DISPLAY = (
    "clonedrive sim: no display (DISPLAY is not set), so no window can open.\n"
    "  - run it on a desktop, or under a virtual display:\n"
    "      xvfb-run -s \"-screen 0 1024x768x24\" clonedrive sim --track lake\n"
    "  - or render headless with the software renderer into an offscreen buffer:\n"
    "      clonedrive sim --track lake --hold w --steps 45 --screenshot sim.png"
)


def run(args: argparse.Namespace) -> int:
    from clonedrive.manual.window import display_available

    scripted = args.screenshot is not None or args.steps is not None
    if args.windowed and not display_available():
        print(NO_DISPLAY, file=sys.stderr)
        return 2
    onscreen = args.windowed or (not args.offscreen and display_available())
    if not onscreen and not (args.offscreen or scripted):
        print(NO_DISPLAY, file=sys.stderr)
        return 2
    steps = args.steps
    if steps is None and (args.screenshot is not None or not onscreen):
        steps = 30
    if steps is not None and steps < 0:
        print("clonedrive sim: --steps must be >= 0", file=sys.stderr)
        return 2
    try:
        host, port = _host_port(args.server)
        config = _manual_config(args, host, port)
        if args.track is not None:
            from clonedrive.world.catalog import load_track

            load_track(args.track)  # a bad name fails here, clearly, before a window opens
    except ValueError as error:  # TrackError is a ValueError
        print(f"clonedrive sim: {error}", file=sys.stderr)
        return 2
    hold = tuple(key.strip().lower() for key in args.hold.split(",") if key.strip())

    from clonedrive.manual.session import DrivingSession
    from clonedrive.manual.window import run_window

    with DrivingSession(config, args.out) as session:
        try:
            summary = run_window(session, onscreen=onscreen, software=args.software,
                                 track=args.track, reverse=args.reverse, hold=hold,
                                 record=args.record, steps=steps, screenshot=args.screenshot)
        except RuntimeError as error:
            if "window" in str(error) or "graphics pipe" in str(error):
                print(f"clonedrive sim: {error}; try --software (no OpenGL) or --offscreen",
                      file=sys.stderr)
                return 1
            raise
    if args.json:
        print(json.dumps(asdict(summary)))
    else:
        print(f"renderer: {summary.renderer}")
        if summary.track:
            print(f"drove {summary.track} for {summary.steps} steps")
        if summary.folder_rows:
            print(f"recorded {summary.rows_recorded} rows; {summary.folder_rows} rows in "
                  f"{summary.out_dir}/driving_log.csv")
        if summary.screenshot:
            print(f"screenshot: {summary.screenshot}")
    return 0


def _host_port(text: str) -> tuple[str, int]:
    host, separator, port = text.rpartition(":")
    if not separator or not host or not port.isdigit():
        raise ValueError(f"--server {text!r}: expected HOST:PORT, e.g. 127.0.0.1:{PORT}")
    return host, int(port)


def _manual_config(args: argparse.Namespace, host: str, port: int):
    from clonedrive.manual.config import ManualConfig

    return ManualConfig(scenery=not args.no_scenery, seed=args.seed,
                        generated_seed=args.generated_seed, header=args.header,
                        relative_paths=args.relative_paths, jpeg_quality=args.jpeg_quality,
                        server_host=host, server_port=port)
