"""``clonedrive evaluate``: drive a model around tracks in closed loop and measure it."""

from __future__ import annotations

import json
import sys

from clonedrive.commands.counts import speed_flag_error
from clonedrive.commands.model_options import (
    add_model_arguments,
    add_steering_arguments,
    load_policy_from_args,
)
from clonedrive.commands.render_options import add_render_arguments, renderer_error
from clonedrive.world.names import TRACK_NAMES_HELP

HELP = "drive a model in closed loop (headless) and measure laps, interventions, CTE"
DESCRIPTION = (
    "Drive a trained model around tracks in the simulator, in-process and headless, and measure "
    "for each (track, speed): laps completed, interventions and autonomy %, off-road events and "
    "where they happened, mean and max |CTE|, steering smoothness, mean speed and distance. "
    "Writes eval.json, a track map per run with the driven path, the frame the network saw at "
    "each off-road event, and with --video an mp4 with a HUD per built-in-track run."
)
#: Example command lines, shown at the end of ``clonedrive evaluate --help``.
EXAMPLES = (
    "clonedrive evaluate runs/x/model.keras --track lake --speed 15 --speed 30",
    "clonedrive evaluate runs/x/model.keras --track mountain --laps 1 --video --out runs/x/eval",
)


def add_arguments(parser) -> None:
    from clonedrive.evaluate.config import EvalConfig

    d = EvalConfig()
    parser.add_argument("model", help="trained model (.keras, .h5 or .onnx)")
    parser.add_argument("--track", action="append", default=None, metavar="NAME",
                        help=f"track to drive (repeatable): {TRACK_NAMES_HELP}; default "
                             f"{', '.join(d.tracks)} (none if only --unseen is "
                             "given)")
    parser.add_argument("--speed", action="append", type=float, default=None, metavar="MPH",
                        help="set speed in mph (repeatable); default "
                             f"{', '.join(f'{v:g}' for v in d.speeds_mph)}")
    parser.add_argument("--laps", type=int, default=d.laps, help="laps to drive per run")
    parser.add_argument("--unseen", type=int, default=d.unseen, metavar="N",
                        help="also drive N generated tracks never used in recording "
                             "(seeds from 1000)")
    parser.add_argument("--unseen-speed", type=float, default=d.unseen_speed_mph, metavar="MPH",
                        help="set speed on the unseen tracks (default: the first --speed)")
    parser.add_argument("--unseen-laps", type=int, default=d.unseen_laps, metavar="N",
                        help="laps on the unseen tracks (default: --laps)")
    parser.add_argument("--video", action="store_true",
                        help="write an mp4 of the center camera with a HUD per built-in run")
    parser.add_argument("--video-saliency", action="store_true",
                        help="with --video: paint the VisualBackProp saliency mask (where the "
                             "network looks) onto the frames")
    add_steering_arguments(parser)
    parser.add_argument("--batch", type=int, default=d.batch,
                        help="runs driven in lock-step by one process (each frame is still "
                             "predicted alone: the figures do not depend on it)")
    parser.add_argument("--workers", type=int, default=d.workers,
                        help="worker processes the runs are spread over, each driving its share "
                             "in lock-step (default: one per CPU core)")
    parser.add_argument("--max-seconds", type=float, default=d.max_seconds, metavar="SECONDS",
                        help="stop each run after this much simulated time (quick checks; "
                             "default: the time limit, 2.5 x the laps' time at the set speed "
                             "+ 30 s)")
    parser.add_argument("--no-scenery", action="store_true",
                        help="road and terrain only (no trees, rocks, barriers)")
    add_render_arguments(parser)
    parser.add_argument("--out", default=None,
                        help="output folder (default: eval/ beside the model)")
    parser.add_argument("--json", action="store_true", help="print eval.json's content")
    add_model_arguments(parser)


def run(args) -> int:
    speed_problem = speed_flag_error(args, "--speed", "--unseen-speed")
    if speed_problem:  # named as the flag the user typed, before anything loads
        print(f"clonedrive evaluate: {speed_problem}", file=sys.stderr)
        return 2
    from pathlib import Path

    from clonedrive.base.paths import prepare_output_folder
    from clonedrive.commands.output_claim import claim
    from clonedrive.evaluate.config import EvalConfig
    from clonedrive.evaluate.results import format_table
    from clonedrive.evaluate.rollout import evaluate
    from clonedrive.world.catalog import load_track
    from clonedrive.world.track import TrackError

    d = EvalConfig()
    tracks = args.track if args.track is not None else ([] if args.unseen else list(d.tracks))
    try:
        resolved = {name: load_track(name) for name in tracks}  # loaded once, passed down
    except TrackError as error:
        print(f"clonedrive evaluate: {error}", file=sys.stderr)
        return 2
    try:
        config = EvalConfig(tracks=tuple(tracks),
                            speeds_mph=tuple(args.speed) if args.speed else d.speeds_mph,
                            laps=args.laps, unseen=args.unseen,
                            unseen_speed_mph=args.unseen_speed, unseen_laps=args.unseen_laps,
                            video=args.video, slow_in_curves=args.slow_in_curves,
                            scenery=not args.no_scenery, batch=args.batch,
                            max_seconds=args.max_seconds, video_saliency=args.video_saliency,
                            workers=args.workers, renderer=args.renderer,
                            full_frame=args.full_frame)
    except ValueError as error:  # --speed nan, -5, 31...
        print(f"clonedrive evaluate: {error}", file=sys.stderr)
        return 2
    problem = renderer_error(args, "evaluate")
    if problem:
        print(problem, file=sys.stderr)
        return 2
    try:
        policy = load_policy_from_args(args, args.model)
    except (FileNotFoundError, ValueError) as error:
        print(f"clonedrive evaluate: {error}", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else Path(args.model).resolve().parent / "eval"
    try:
        prepare_output_folder(out)  # a read-only or full place fails now, not after driving
    except ValueError as error:
        print(f"clonedrive evaluate: {error}", file=sys.stderr)
        return 2
    lock = claim("evaluate", out, inputs=[args.model])
    if lock is None:
        return 1
    with lock:
        report = evaluate(policy, config, out, progress=not args.json,
                          model_path=str(args.model),
                          model_options={"trust": args.trust_model, "runtime": args.runtime},
                          tracks=resolved)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_table(report))
        print(f"wrote {out / 'eval.json'}")
    return 0
