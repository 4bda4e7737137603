"""``clonedrive dagger``: DAgger -- the network drives, the expert labels, retrain, repeat."""

from __future__ import annotations

import json
import sys

from clonedrive.commands.counts import (
    MAX_EPOCHS,
    MAX_ITERATIONS,
    MAX_LAPS,
    MAX_UNSEEN,
    MAX_WORKERS,
    count,
    speed_flag_error,
)
from clonedrive.commands.render_options import add_render_arguments, renderer_error
from clonedrive.world.names import TRACK_NAMES_HELP

HELP = "DAgger: the network drives (mixed with the expert), the expert labels, retrain, repeat"
DESCRIPTION = (
    "Start from a training run (clonedrive train --out BASE) and iterate DAgger (Ross, Gordon & "
    "Bagnell 2011): each iteration the network drives the collection tracks, mixed with the "
    "expert (its share beta decays per iteration), with a safety takeover by the expert when "
    "the car is about to leave the road (counted); the expert labels every frame with its "
    "steering and target speed; the frames are saved as Udacity-format recordings, aggregated "
    "with the base data, and the network is retrained from its previous weights and evaluated "
    "in closed loop. Plain cloning with as many extra expert labels is trained and evaluated "
    "for comparison. Writes iter_NN/{data,train,eval}/, plain/, dagger.json and dagger.png."
)
#: Example command lines, shown at the end of ``clonedrive dagger --help``.
EXAMPLES = (
    "clonedrive dagger runs/x --out runs/x-dagger --iterations 3",
)


def add_arguments(parser) -> None:
    from clonedrive.pipelines.dagger.config import DaggerConfig

    d = DaggerConfig()
    parser.add_argument("base", help="training run folder (model.keras, config.json, "
                                     "recipe.toml) to start from")
    parser.add_argument("--out", required=True, help="folder to write (reused when re-run)")
    parser.add_argument("--iterations", type=count(MAX_ITERATIONS), default=d.iterations)
    parser.add_argument("--beta", type=float, default=d.beta,
                        help="share of steps the expert drives in iteration 1")
    parser.add_argument("--beta-decay", type=float, default=d.beta_decay,
                        help="beta is multiplied by this each iteration")
    parser.add_argument("--track", action="append", default=None, metavar="NAME",
                        help=f"collection track: {TRACK_NAMES_HELP} (repeatable; default "
                             f"{' '.join(d.tracks)})")
    parser.add_argument("--laps", type=count(MAX_LAPS),
                        default=d.laps, help="laps per track and iteration")
    parser.add_argument("--speed", type=float, default=d.speed_mph, metavar="MPH",
                        help="set speed (a cap) for collecting and evaluating")
    parser.add_argument("--epochs", type=count(MAX_EPOCHS), default=d.epochs,
                        help="training epochs per iteration, from the previous weights")
    parser.add_argument("--lr", dest="learning_rate", type=float, default=d.learning_rate)
    parser.add_argument("--eval-track", action="append", default=None, metavar="NAME",
                        help=f"evaluation track (repeatable; default {' '.join(d.eval_tracks)})")
    parser.add_argument("--eval-laps", type=count(MAX_LAPS), default=d.eval_laps)
    parser.add_argument("--unseen", type=count(MAX_UNSEEN), default=d.eval_unseen, metavar="N",
                        help="also evaluate on N generated tracks never collected on")
    parser.add_argument("--bench-split", action="append", default=None, metavar="SPLIT",
                        help="evaluate each iteration on this benchmark split (repeatable; "
                             "default: the --eval-track and --unseen tracks with evaluate)")
    parser.add_argument("--suite", default=d.bench_suite, help="benchmark suite (--bench-split)")
    parser.add_argument("--workers", type=count(MAX_WORKERS), default=d.workers,
                        help="bench worker processes")
    parser.add_argument("--no-plain", dest="plain", action="store_false",
                        help="skip the plain-cloning comparison")
    parser.add_argument("--plain-each", action="store_true",
                        help="run the plain-cloning comparison at every iteration's label "
                             "count, not only the last (a curve beside DAgger's; costs as many "
                             "more trainings)")
    parser.add_argument("--plain-noise", type=float, default=d.plain_noise, metavar="NOISE",
                        help="the expert's steering noise while it records the plain-cloning "
                             "comparison's labels (the labels stay clean); 0 is textbook "
                             "behavioural cloning, on the expert's own states only")
    parser.add_argument("--human", action="append", default=None, metavar="FOLDER",
                        help="a recording of a person's takeovers (clonedrive web, takeover "
                             "mode: HG-DAgger labels), aggregated from iteration 1 (repeatable)")
    parser.add_argument("--max-seconds", type=float, default=None,
                        help="cap on simulated seconds per episode (quick runs)")
    parser.add_argument("--no-scenery", dest="scenery", action="store_false")
    add_render_arguments(parser)
    parser.add_argument("--seed", type=int, default=d.seed)
    parser.add_argument("--json", action="store_true", help="print dagger.json's content")


def run(args) -> int:
    speed_problem = speed_flag_error(args, "--speed")
    if speed_problem:  # named as the flag the user typed, before anything loads
        print(f"clonedrive dagger: {speed_problem}", file=sys.stderr)
        return 2
    from clonedrive.bench.suite import load_suite
    from clonedrive.data.output_lock import claim_output
    from clonedrive.pipelines.dagger.config import DaggerConfig
    from clonedrive.pipelines.dagger.figures import format_table
    from clonedrive.pipelines.dagger.loop import run_dagger
    from clonedrive.world.catalog import load_track
    from clonedrive.world.track import TrackError

    d = DaggerConfig()
    problem = renderer_error(args, "dagger")
    if problem:
        print(problem, file=sys.stderr)
        return 2
    try:
        config = DaggerConfig(
            iterations=args.iterations, beta=args.beta, beta_decay=args.beta_decay,
            tracks=tuple(args.track or d.tracks), laps=args.laps, speed_mph=args.speed,
            epochs=args.epochs, learning_rate=args.learning_rate,
            eval_tracks=tuple(args.eval_track or d.eval_tracks), eval_laps=args.eval_laps,
            eval_unseen=args.unseen, bench_suite=args.suite,
            bench_splits=tuple(args.bench_split or ()), workers=args.workers, plain=args.plain,
            plain_each=args.plain_each, plain_noise=args.plain_noise,
            max_seconds=args.max_seconds,
            scenery=args.scenery, seed=args.seed, human=tuple(args.human or ()),
            renderer=args.renderer, full_frame=args.full_frame)
        for name in (*config.tracks, *config.eval_tracks):
            load_track(name)
        if config.bench_splits:  # a misspelt split is named now, not after the first lap
            load_suite(config.bench_suite).episodes(config.bench_splits)
    except (ValueError, TrackError) as error:  # a flag
        print(f"clonedrive dagger: {error}", file=sys.stderr)
        return 2
    try:  # the base run, the output folder and what an earlier run left there
        with claim_output("dagger", args.out, inputs=[args.base]):
            report = run_dagger(config, args.base, args.out, progress=not args.json)
    except (ValueError, FileNotFoundError) as error:
        print(f"clonedrive dagger: {error}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_table(report))
    return 0
