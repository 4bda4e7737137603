"""``clonedrive demo``: from nothing to a driving model, measured, with a write-up."""

from __future__ import annotations

import sys

from clonedrive.commands.counts import MAX_EPOCHS, MAX_UNSEEN, MAX_WORKERS, count

HELP = "record expert data, train, evaluate in closed loop and write the report (the main job)"
DESCRIPTION = (
    "From an empty folder, follow a recipe: record its data with the expert, train a "
    "network with its settings, evaluate the model in closed loop as the recipe says (the "
    "built-in 'best': lake and mountain at 15 and 30 mph and 10 generated tracks it never saw "
    "at 30 mph, with videos), bench it where the recipe says (built-in 'best': the benchmark's "
    "hard dev tier), and write report.md / report.html. The model file carries the "
    "recipe's driving settings, so `clonedrive evaluate` and `clonedrive drive` drive it as the "
    "demo did. Finished stages are reused when run again on the same folder. --quick runs a "
    "small version of every stage in about a minute."
)
#: Example command lines, shown at the end of ``clonedrive demo --help``.
EXAMPLES = (
    "clonedrive demo                      # the whole job into runs/demo/, recipe 'best'",
    "clonedrive demo --recipe writeup --out runs/writeup   # the seed write-up's system",
    "clonedrive demo --recipe my.toml     # a copy of a recipe file, edited",
    "clonedrive demo --quick              # every stage, small, in a minute: runs/demo-quick/",
)


def add_arguments(parser) -> None:
    from clonedrive.pipelines.demo import DEFAULT_RUN_DIR, DEMO_MODELS, QUICK_RUN_DIR, DemoConfig
    from clonedrive.recipes.book import recipe_choices_text

    defaults = DemoConfig()
    parser.add_argument("--out", default=None,
                        help=f"run folder (default {DEFAULT_RUN_DIR}, with --quick "
                             f"{QUICK_RUN_DIR})")
    parser.add_argument("--recipe", default=defaults.recipe, metavar="NAME|FILE",
                        help=f"a built-in recipe ({recipe_choices_text()}) or a recipe file: "
                             f"what to record, how to train and drive (default "
                             f"{defaults.recipe}); the files are in clonedrive/recipes/")
    parser.add_argument("--quick", action="store_true", default=defaults.quick,
                        help="small data, 2 epochs, one short evaluation (exercises every stage)")
    parser.add_argument("--epochs", type=count(MAX_EPOCHS), default=defaults.epochs,
                        help="override the recipe's training epochs")
    parser.add_argument("--unseen", type=count(MAX_UNSEEN), default=defaults.unseen, metavar="N",
                        help="number of unseen generated tracks to evaluate on (default: the "
                             "recipe's, 10 for the built-in ones)")
    parser.add_argument("--model", default=defaults.model, choices=DEMO_MODELS,
                        help="override the recipe's network architecture")
    parser.add_argument("--no-video", dest="video", action="store_false", default=defaults.video,
                        help="skip the mp4s")
    parser.add_argument("--workers", type=count(MAX_WORKERS), default=defaults.workers,
                        help="worker processes for recording and evaluation (default: one per "
                             "CPU core)")
    parser.add_argument("--seed", type=int, default=defaults.seed,
                        help="seeds recording and training")


def run(args) -> int:
    from clonedrive.commands.output_claim import claim
    from clonedrive.pipelines.demo import DEFAULT_RUN_DIR, QUICK_RUN_DIR, DemoConfig, run_demo

    if args.out is None:
        args.out = QUICK_RUN_DIR if args.quick else DEFAULT_RUN_DIR

    try:
        config = DemoConfig(recipe=args.recipe, quick=args.quick, epochs=args.epochs,
                            unseen=args.unseen, model=args.model, video=args.video, seed=args.seed,
                            workers=args.workers)
        from clonedrive.recipes.book import load_recipe_file

        load_recipe_file(config.recipe)  # a bad recipe is refused before anything runs
    except (ValueError, FileNotFoundError) as error:
        print(f"clonedrive demo: {error}", file=sys.stderr)
        return 2
    lock = claim("demo", args.out)
    if lock is None:
        return 1
    from clonedrive.pipelines.demo import DemoFolderError

    with lock:
        try:
            summary = run_demo(config, args.out)
        except DemoFolderError as error:
            print(f"clonedrive demo: {error}", file=sys.stderr)
            return 1
    stages = ", ".join(f"{name} {stage['seconds']:.0f} s"
                       for name, stage in summary["stages"].items())
    print(f"demo finished in {summary['total_seconds']:.0f} s ({stages})")
    print(f"report: {args.out}/report.html")
    return 0
