"""``clonedrive replay``: a model in closed loop through real Udacity logs, by viewpoint
synthesis."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from clonedrive.commands.model_options import (
    add_model_arguments,
    add_steering_arguments,
    load_policy_from_args,
)

HELP = "closed-loop check of a model on real Udacity logs: autonomy, interventions, offset"
DESCRIPTION = (
    "Drive the model through each LOG_DIR (a driving_log.csv and IMG/ as the Udacity simulator "
    "writes them) in closed loop: the car keeps a lateral offset and heading error from the "
    "path the human drove, moved each frame by the difference between the model's steering and "
    "the human's (a kinematic bicycle at the recorded speed), and the model sees the recorded "
    "frame re-rendered for that offset and heading (flat road below the horizon, infinitely far "
    "above; the side cameras fill the edges where the log has them, and their offsets and the "
    "horizon are fitted from its images). Past --max-offset an intervention puts the car back "
    "on the path. Reports autonomy = (1 - interventions x 6 s / elapsed) x 100, interventions "
    "per km, the mean |offset| and the steering jitter. A log splits into episodes where its image "
    "timestamps jump; a stationary, speedless or too short log is refused. Writes replay.json "
    "and replay.png (offset over distance), and with --video replay.mp4, into --out."
)
#: Example command lines, shown at the end of ``clonedrive replay --help``.
EXAMPLES = (
    "clonedrive replay runs/x/model.keras ~/udacity/lake_recording --out runs/x/replay",
    "clonedrive replay runs/x/model.keras ~/udacity/lake ~/udacity/mountain --video",
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from clonedrive.replay.episode import ReplayConfig
    from clonedrive.replay.motion import VEHICLE_MODELS

    defaults = ReplayConfig()
    parser.add_argument("model", help="model file (.keras, .h5 or .onnx)")
    parser.add_argument("log_dirs", metavar="LOG_DIR", nargs="+",
                        help="folder holding driving_log.csv + IMG/")
    parser.add_argument("--out", default=None,
                        help="output folder (default: replay/<first log folder name>/ beside the "
                             "model)")
    parser.add_argument("--max-offset", type=float, default=defaults.max_offset_m, metavar="M",
                        help="an intervention when the car is further than M metres from the "
                             "recorded path")
    parser.add_argument("--no-calibrate", action="store_true",
                        help="use the default side-camera offsets and horizon instead of fitting "
                             "them to a three-camera log")
    parser.add_argument("--vehicle-model", choices=VEHICLE_MODELS,
                        default=defaults.vehicle_model,
                        help="how the car moves off the recorded path: a kinematic bicycle, or "
                             "the simulator's dynamic single-track model (tyre slip, yaw "
                             "inertia) (default: %(default)s)")
    parser.add_argument("--video", action="store_true",
                        help="also write replay.mp4: the frames the model saw, with a HUD")
    parser.add_argument("--json", action="store_true", help="print replay.json's content")
    add_model_arguments(parser)
    add_steering_arguments(parser, speed=False)


def run(args: argparse.Namespace) -> int:
    from clonedrive.base.paths import check_output_folder, safe_stem
    from clonedrive.commands.output_claim import claim
    from clonedrive.replay.episode import ReplayConfig
    from clonedrive.replay.output import format_summary

    try:
        config = ReplayConfig(max_offset_m=args.max_offset, calibrate=not args.no_calibrate,
                              vehicle_model=args.vehicle_model)
    except ValueError as error:
        print(f"clonedrive replay: {error}", file=sys.stderr)
        return 2
    first = Path(args.log_dirs[0])
    out = Path(args.out) if args.out else (
        Path(args.model).resolve().parent / "replay" / safe_stem(first.resolve().name))
    try:
        check_output_folder(out)
    except ValueError as error:
        print(f"clonedrive replay: {error}", file=sys.stderr)
        return 1
    lock = claim("replay", out, inputs=[args.model, *args.log_dirs])
    if lock is None:  # another replay writes there, or it is (inside) an input
        return 1
    with lock:
        report = _replay(args, out, config)
    if report is None:
        return 1
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_summary(report))
        print("wrote " + ", ".join(str(out / name) for name in report["files"].values()))
    return 0


def _replay(args: argparse.Namespace, out: Path, config) -> dict | None:
    """replay.json's content, or None after printing why the model or a log was refused."""
    from clonedrive.data.driving_log import DrivingLogError
    from clonedrive.replay.output import replay

    try:
        policy = load_policy_from_args(args, args.model)
        return replay(policy, args.log_dirs, out, config, video=args.video,
                      model_path=str(args.model))
    except (FileNotFoundError, ValueError, DrivingLogError) as error:
        print(f"clonedrive replay: {error}", file=sys.stderr)
        return None
