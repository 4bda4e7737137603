"""``clonedrive drive``: serve a model to the Udacity simulator, a drop-in for drive.py."""

from __future__ import annotations

import argparse
import logging
import sys

from clonedrive.udacity_spec import PORT, SET_SPEED_MPH

HELP = "serve a steering model to the Udacity simulator (drop-in for drive.py)"
DESCRIPTION = (
    "Load a Keras steering model (.keras, or legacy .h5) and answer the Udacity simulator's "
    "telemetry on ws://HOST:PORT/socket.io/ with steering from the model and throttle from a PI "
    "speed controller, as Udacity's drive.py does. Start the simulator in Autonomous Mode. "
    "With IMAGE_FOLDER, every received frame is saved there as YYYY_MM_DD_HH_MM_SS_mmm.jpg (UTC); "
    "turn them into a video with `clonedrive video IMAGE_FOLDER`. Binds 127.0.0.1 unless --host "
    "says otherwise."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", help="Keras model file (.keras or .h5)")
    parser.add_argument(
        "image_folder", nargs="?", default=None, help="save received frames in this folder"
    )
    parser.add_argument("--speed", type=float, default=SET_SPEED_MPH, help="set speed, mph")
    parser.add_argument(
        "--slow-in-curves",
        action="store_true",
        help="lower the target speed as |steering| grows (down to 40%% of --speed)",
    )
    parser.add_argument(
        "--host", default="127.0.0.1", help="interface to bind; 0.0.0.0 serves other machines"
    )
    parser.add_argument("--port", type=int, default=PORT,
                        help=f"TCP port (the simulator uses {PORT})")
    parser.add_argument(
        "--status-every", type=float, default=5.0, help="seconds between status lines; 0: none"
    )


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", datefmt="%H:%M:%S")
    logging.getLogger("websockets").setLevel(logging.WARNING)  # our own lines say enough
    if not 0 <= args.port <= 65535:
        print(f"error: --port {args.port} is not a TCP port", file=sys.stderr)
        return 2
    if args.speed < 0 or args.speed > 30:
        print(f"error: --speed {args.speed} mph is outside 0..30", file=sys.stderr)
        return 2

    from clonedrive.drivers.network import load_policy
    from clonedrive.udacity.server import DriveServer

    try:
        policy = load_policy(
            args.model, set_speed_mph=args.speed, slow_in_curves=args.slow_in_curves
        )
    except (FileNotFoundError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(
            f"note: listening on {args.host}: other machines can connect and drive", file=sys.stderr
        )
    server = DriveServer(
        policy,
        host=args.host,
        port=args.port,
        image_folder=args.image_folder,
        status_interval_s=args.status_every,
    )
    try:
        server.serve_forever()
    except OSError as error:
        print(f"error: cannot listen on {args.host}:{args.port}: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        pass
    stats = server.stats()
    print(
        f"served {stats.connections} connection(s): {stats.steer} steer, {stats.manual} manual, "
        f"{stats.safe} safe replies, {stats.bad_total} bad message(s)",
        file=sys.stderr,
    )
    return 0
