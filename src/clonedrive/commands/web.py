"""``clonedrive web``: drive, watch, record and take over from a browser page."""

from __future__ import annotations

import argparse
import sys

from clonedrive.commands.model_options import add_model_arguments, load_policy_from_args
from clonedrive.commands.record import add_log_format_arguments
from clonedrive.world.names import TRACK_NAMES_HELP

HELP = "drive, watch, record and take over from a browser page (headless servers too)"
DESCRIPTION = (
    "Serve one page that shows the simulator live (the center camera or all three, 15 frames/s, "
    "with the window's HUD) and drives it: keyboard (W/S, A/D, arrows), mouse or finger on the "
    "picture, a browser gamepad. Modes: manual, the expert autopilot, a model (--model, any "
    "file `clonedrive drive` accepts) and model with takeover: touching any control takes the "
    "car, letting go hands it back; each takeover is counted and, while recording, only the "
    "person's rows are recorded (HG-DAgger labels for `clonedrive dagger --human`). The record "
    "toggle writes an ordinary Udacity-format recording (driving_log.csv, IMG/, config.json) "
    "into --out. Binds 127.0.0.1 and prints the page's URL with a random token; requests "
    "without the token, WebSockets from other sites' pages and unknown Host names are refused."
)
#: Example command lines, shown at the end of ``clonedrive web --help``.
EXAMPLES = (
    "clonedrive web --track lake --out data/web   # then open the printed URL",
    "clonedrive web --model runs/x/model.keras --port 8888",
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from clonedrive.web.app import WebSession
    from clonedrive.web.config import VIEWS, WebConfig

    d, s = WebConfig(), WebSession()
    parser.add_argument("--track", default=s.track,
                        help=f"track to start on: {TRACK_NAMES_HELP} (the page can switch)")
    parser.add_argument("--reverse", action="store_true", help="start driving backwards")
    parser.add_argument("--look", default=s.look,
                        help="scene look to start in (clear, or a recording look: record --look)")
    parser.add_argument("--model", default=None, metavar="FILE",
                        help="model for the model and takeover modes (.keras, .h5 or .onnx)")
    parser.add_argument("--speed", type=float, default=None, metavar="MPH",
                        help="the model's set speed (default: drive's)")
    add_model_arguments(parser)
    parser.add_argument("--out", default=s.out_dir, help="folder the record toggle records into")
    parser.add_argument("--host", default=d.host,
                        help="IP address to bind; 0.0.0.0 lets anyone on the network with the "
                             "URL drive")
    parser.add_argument("--port", type=int, default=d.port, help="TCP port (0: any free one)")
    parser.add_argument("--view", choices=VIEWS, default=d.view, help="first view")
    parser.add_argument("--stream-quality", type=int, default=d.jpeg_quality, metavar="Q",
                        help="JPEG quality of the live view, 1-100")
    parser.add_argument("--no-scenery", action="store_true",
                        help="road and terrain only (no trees, rocks...): quicker")
    parser.add_argument("--seed", type=int, default=s.seed, help="the scene's seed")
    add_log_format_arguments(parser)  # the recording, as `clonedrive record` writes it


def run(args: argparse.Namespace) -> int:
    try:
        config, setup, manual = _configs(args)
        from clonedrive.web.app import check_port

        check_port(config.host, config.port)  # before a model or a track loads
    except ValueError as error:  # TrackError is a ValueError
        return _fail(str(error))
    except OSError as error:
        return _fail(error.strerror or str(error))
    if not config.loopback_only:
        print(f"clonedrive web: warning: listening on {config.host}: anyone on the network with "
              "the URL can drive the car and record into --out", file=sys.stderr)
    policy = None
    if args.model is not None:
        options = {} if args.speed is None else {"set_speed_mph": args.speed}
        try:
            policy = load_policy_from_args(args, args.model, **options)
        except (FileNotFoundError, ValueError) as error:
            return _fail(str(error))
    from clonedrive.commands.output_claim import claim

    lock = claim("web", args.out, inputs=[args.model] if args.model else [])
    if lock is None:  # another web server records there, or --out is (inside) the model
        return 1
    with lock:
        return _serve(config, setup, policy, args.model, manual)


def _serve(config, setup, policy, model: str | None, manual) -> int:
    """Serve the page until Ctrl-C; its --out held by the caller."""
    from clonedrive.web.app import WebApp

    app = WebApp(config, setup, policy=policy, model_name=model or "model",
                 manual_config=manual)
    try:
        app.open()
    except OSError as error:
        app.close()
        return _fail(f"{error.strerror or error}: choose another port with --port")
    print("clonedrive web: open this page in a browser (Ctrl-C stops):", file=sys.stderr)
    print(app.url, flush=True)
    try:
        app.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        app.close()
    session = app.controller.session
    if session.folder_rows:
        print(f"recorded {session.rows_recorded} rows; {session.folder_rows} rows in "
              f"{session.out_dir}/driving_log.csv", file=sys.stderr)
    return 0


def _configs(args: argparse.Namespace):
    from clonedrive.manual.config import ManualConfig
    from clonedrive.sim.conditions import TRAINING_LOOKS
    from clonedrive.web.app import WebSession
    from clonedrive.web.config import WebConfig
    from clonedrive.world.catalog import load_track

    if args.look != "clear" and args.look not in TRAINING_LOOKS:
        raise ValueError(f"--look {args.look!r} is not one of {', '.join(TRAINING_LOOKS)}")
    if args.speed is not None and not 0 < args.speed <= 30:  # also nan
        raise ValueError(f"--speed {args.speed} mph is outside (0, 30]")
    config = WebConfig(host=args.host, port=args.port, view=args.view,
                       jpeg_quality=args.stream_quality)
    load_track(args.track)  # a bad name fails here, clearly
    setup = WebSession(track=args.track, reverse=args.reverse, look=args.look, out_dir=args.out,
                       scenery=not args.no_scenery, seed=args.seed)
    manual = ManualConfig(scenery=setup.scenery, seed=args.seed, header=args.header,
                          relative_paths=args.relative_paths, jpeg_quality=args.jpeg_quality)
    return config, setup, manual


def _fail(message: str) -> int:
    print(f"clonedrive web: {message}", file=sys.stderr)
    return 2
