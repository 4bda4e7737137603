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


def add_arguments(parser) -> None:
    parser.add_argument("--out", default="runs/demo", help="run folder")
    parser.add_argument("--quick", action="store_true",
                        help="small data, 2 epochs, one short evaluation (exercises every stage)")
    parser.add_argument("--epochs", type=int, default=None, help="override the training epochs")
    parser.add_argument("--unseen", type=int, default=None, metavar="N",
                        help="number of unseen generated tracks to evaluate on (default 10)")
    parser.add_argument("--model", default="fast", choices=("fast", "seed", "pilotnet"),
                        help="network architecture")
    parser.add_argument("--no-video", action="store_true", help="skip the mp4s")
    parser.add_argument("--seed", type=int, default=0, help="seeds recording and training")


def run(args) -> int:
    from clonedrive.demo import DemoConfig, run_demo

    if args.epochs is not None and args.epochs < 1:
        print("error: --epochs must be at least 1", file=sys.stderr)
        return 2
    if args.unseen is not None and args.unseen < 0:
        print("error: --unseen must be >= 0", file=sys.stderr)
        return 2
    config = DemoConfig(quick=args.quick, epochs=args.epochs, unseen=args.unseen,
                        model=args.model, video=not args.no_video, seed=args.seed)
    summary = run_demo(config, args.out)
    stages = ", ".join(f"{name} {stage['seconds']:.0f} s"
                       for name, stage in summary["stages"].items())
    print(f"demo finished in {summary['total_seconds']:.0f} s ({stages})")
    print(f"report: {args.out}/report.html")
    return 0
