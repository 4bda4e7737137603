"""``clonedrive drive``: serve a model to the Udacity simulator, a drop-in for drive.py."""

from __future__ import annotations

import argparse
import errno
import logging
import socket
import sys

from clonedrive.base.udacity_spec import SET_SPEED_MPH
from clonedrive.commands.counts import MAX_CONNECTIONS, count, speed_flag_error
from clonedrive.commands.model_options import (
    add_model_arguments,
    add_steering_arguments,
    load_policy_from_args,
)
from clonedrive.udacity.server_config import DriveServerConfig

HELP = "serve a steering model to the Udacity simulator (drop-in for drive.py)"
DESCRIPTION = (
    "Load a steering model (.keras, .h5 including students' Keras 2 files, or .onnx) and "
    "answer the Udacity simulator's telemetry on ws://HOST:PORT/socket.io/ with steering from "
    "the model and throttle from a PI speed controller, as Udacity's drive.py does. Start the "
    "simulator in Autonomous Mode. With IMAGE_FOLDER, every received frame is saved there as "
    "YYYY_MM_DD_HH_MM_SS_mmm.jpg (UTC); turn them into a video with `clonedrive video "
    "IMAGE_FOLDER`. Replies use the decimal separator the simulator's telemetry uses (comma "
    "locales). Binds 127.0.0.1 unless --host says otherwise."
)
#: Example command lines, shown at the end of ``clonedrive drive --help``.
EXAMPLES = (
    "clonedrive drive runs/x/model.keras   # then start the simulator in Autonomous Mode",
    "clonedrive drive runs/x/model.keras frames/ --port 4568",
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", help="model file (.keras, .h5 or .onnx)")
    parser.add_argument(
        "image_folder", nargs="?", default=None, help="save received frames in this folder"
    )
    parser.add_argument("--speed", type=float, default=SET_SPEED_MPH, help="set speed, mph")
    add_steering_arguments(parser)
    defaults = DriveServerConfig()
    parser.add_argument("--host", default=defaults.host,
                        help="IP address to bind; 0.0.0.0 serves other machines")
    parser.add_argument("--port", type=int, default=defaults.port,
                        help=f"TCP port (the simulator uses {defaults.port})")
    parser.add_argument("--status-every", type=float, default=defaults.status_interval_s,
                        help="seconds between status lines; 0: none")
    parser.add_argument("--max-connections", type=count(MAX_CONNECTIONS),
                        default=defaults.max_connections,
                        help="clients served at once; more are refused (503)")
    parser.add_argument("--idle-timeout", type=float, default=defaults.idle_timeout_s,
                        metavar="SECONDS",
                        help="close a connection that sends no telemetry for this long, so idle "
                             "clients cannot lock the simulator out")
    parser.add_argument("--allow-origin", action="append", default=[], metavar="ORIGIN",
                        help="accept WebSocket upgrades from this browser origin (repeatable; "
                             "by default an upgrade with an Origin header is refused unless it "
                             "is the server's own, http://HOST:PORT, as Python clients send: "
                             "the simulator sends none, a web page always does)")
    parser.add_argument("--allow-host", action="append", default=[], metavar="NAME",
                        help="also accept this name in the Host header (repeatable; by default "
                             "only the bound address, loopback names and, on 0.0.0.0, IP "
                             "addresses)")
    parser.add_argument("--image-folder-max-mb", type=float,
                        default=defaults.image_folder_max_mb, metavar="MB",
                        help="stop saving frames once IMAGE_FOLDER holds this much")
    add_model_arguments(parser)


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", datefmt="%H:%M:%S")
    logging.getLogger("websockets").setLevel(logging.WARNING)  # our own lines say enough
    speed_problem = speed_flag_error(args, "--speed") if args.speed != 0 else None
    if speed_problem:  # 0 parks the car, as drive.py allows
        print(f"clonedrive drive: {speed_problem}", file=sys.stderr)
        return 2
    try:
        config = DriveServerConfig(
            host=args.host, port=args.port, image_folder=args.image_folder,
            status_interval_s=args.status_every, max_connections=args.max_connections,
            idle_timeout_s=args.idle_timeout, allowed_origins=tuple(args.allow_origin),
            allowed_hosts=tuple(args.allow_host), image_folder_max_mb=args.image_folder_max_mb)
    except ValueError as error:
        print(f"clonedrive drive: {error}", file=sys.stderr)
        return 2

    busy = _port_problem(args.host, args.port)
    if busy:  # checked before the model loads, which takes seconds
        print(f"clonedrive drive: {busy}", file=sys.stderr)
        return 1
    from clonedrive.udacity.server import DriveServer

    try:
        policy = load_policy_from_args(args, args.model, set_speed_mph=args.speed)
    except (FileNotFoundError, ValueError) as error:
        print(f"clonedrive drive: {error}", file=sys.stderr)
        return 1
    server = DriveServer(policy, config)
    try:
        server.serve_forever()
    except ValueError as error:  # the image folder cannot be written
        print(f"clonedrive drive: {error}", file=sys.stderr)
        return 1
    except OSError as error:
        print(f"clonedrive drive: cannot listen on {args.host}:{args.port}: "
              f"{error.strerror or error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        pass
    stats = server.stats()
    print(
        f"served {stats.connections} connection(s): {stats.steer} steer, {stats.manual} manual, "
        f"{stats.safe} safe replies, {stats.bad_total} bad message(s), "
        f"{sum(stats.refused.values())} refused, {stats.idle_closed} closed idle, "
        f"{stats.nan_predictions} NaN prediction(s)",
        file=sys.stderr,
    )
    return 0


def _port_problem(host: str, port: int) -> str | None:
    """Why the server could not listen on ``host:port``, with the fix, or None if it can."""
    try:
        with socket.create_server((host, port), reuse_port=False):
            return None
    except OSError as error:
        if error.errno == errno.EADDRINUSE:
            return (f"port {port} on {host} is already in use (another drive server or "
                    f"simulator?); choose another with --port, e.g. --port {port + 1}")
        return f"cannot listen on {host}:{port}: {error.strerror or error}"
