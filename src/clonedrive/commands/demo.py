"""``clonedrive demo``: from nothing to a driving model, measured, with a write-up."""

from __future__ import annotations

import sys

HELP = "record expert data, train, evaluate in closed loop and write the report (the main job)"
DESCRIPTION = (
    "From an empty folder: record the write-up's data with the expert driver (centred laps, "
    "left/right edge laps relabelled with +-0.25, sharp turns, the mountain track both ways, its "
    "turns and hairpin), balance, split and train a network, evaluate it in closed loop (lake at "
    "15 and 30 mph, mountain at 15 and 25 mph, unseen generated tracks at 20 mph, with videos), "
    "and write report.md / report.html. Finished stages are reused when run again on the same "
    "folder. --quick runs a small version of every stage in about a minute."
)
#: Example command lines, shown at the end of ``clonedrive demo --help``.
EXAMPLES = (
    "clonedrive demo                      # the whole job into runs/demo/",
    "clonedrive demo --quick --out runs/q  # every stage, small, in about a minute",
)


def add_arguments(parser) -> None:
    from clonedrive.demo import DEFAULT_RUN_DIR, DEMO_MODELS, DemoConfig

    defaults = DemoConfig()
    parser.add_argument("--out", default=DEFAULT_RUN_DIR, help="run folder")
    parser.add_argument("--quick", action="store_true", default=defaults.quick,
                        help="small data, 2 epochs, one short evaluation (exercises every stage)")
    parser.add_argument("--epochs", type=int, default=defaults.epochs,
                        help="override the training epochs")
    parser.add_argument("--unseen", type=int, default=defaults.unseen, metavar="N",
                        help="number of unseen generated tracks to evaluate on (default 10)")
    parser.add_argument("--model", default=defaults.model, choices=DEMO_MODELS,
                        help="network architecture")
    parser.add_argument("--no-video", dest="video", action="store_false", default=defaults.video,
                        help="skip the mp4s")
    parser.add_argument("--workers", type=int, default=defaults.workers,
                        help="worker processes for recording and evaluation (default: one per "
                             "CPU core)")
    parser.add_argument("--seed", type=int, default=defaults.seed,
                        help="seeds recording and training")


def run(args) -> int:
    from clonedrive.commands.output_claim import claim
    from clonedrive.demo import DemoConfig, run_demo

    try:
        config = DemoConfig(quick=args.quick, epochs=args.epochs, unseen=args.unseen,
                            model=args.model, video=args.video, seed=args.seed,
                            workers=args.workers)
    except ValueError as error:
        print(f"clonedrive demo: {error}", file=sys.stderr)
        return 2
    lock = claim("demo", args.out)
    if lock is None:
        return 1
    with lock:
        summary = run_demo(config, args.out)
    stages = ", ".join(f"{name} {stage['seconds']:.0f} s"
                       for name, stage in summary["stages"].items())
    print(f"demo finished in {summary['total_seconds']:.0f} s ({stages})")
    print(f"report: {args.out}/report.html")
    return 0
