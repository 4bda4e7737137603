"""``clonedrive bench``: drive models through a benchmark suite and write a leaderboard."""

from __future__ import annotations

import json
import sys

from clonedrive.bench import DEFAULT_SUITE
from clonedrive.commands.model_options import (
    add_model_arguments,
    add_steering_arguments,
    steering_options,
)

HELP = "drive models through a versioned benchmark suite (splits, conditions) in parallel"
DESCRIPTION = (
    "Drive one or more models through every split of a benchmark suite (built in: v2; or a "
    ".toml file copied from it): seen tracks, new generated tracks at three difficulties, "
    "held-out conditions. The expert drives each track and speed cap once as the reference. "
    "Writes bench.json, leaderboard.md and leaderboard.html with plots. Give models as PATH or "
    "LABEL=PATH; models with the same label (one per training seed) are reported as mean +- "
    "std. Episodes run in batches on --workers processes (default: one per CPU core), or on "
    "Ray with --ray; the results are the same either way."
)
#: Example command lines, shown at the end of ``clonedrive bench --help``.
EXAMPLES = (
    "clonedrive bench runs/x/model.keras --out runs/x/bench",
    "clonedrive bench a=runs/a/model.keras b=runs/b/model.keras --split new-tracks-hard",
)


def add_arguments(parser) -> None:
    parser.add_argument("models", nargs="+", metavar="MODEL", help="PATH or LABEL=PATH")
    parser.add_argument("--suite", default=DEFAULT_SUITE,
                        help=f"built-in suite name or a suite .toml (default {DEFAULT_SUITE})")
    parser.add_argument("--split", action="append", default=None, metavar="NAME",
                        help="run only this split (repeatable)")
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="worker processes (default: one per CPU core)")
    parser.add_argument("--ray", default=None, metavar="auto|ADDRESS",
                        help="run the batches as Ray tasks (pip install 'clonedrive[cluster]')")
    parser.add_argument("--batch", type=int, default=4,
                        help="episodes one worker drives in lock-step")
    parser.add_argument("--slow-in-curves", action="store_true",
                        help="reduce the target speed as the predicted steering grows "
                             "(default: drive.py parity, the set speed throughout)")
    parser.add_argument("--offline-data", action="append", default=None, metavar="DIR",
                        help="held-out recordings: report each model's offline MSE beside its "
                             "closed-loop figures (repeatable)")
    parser.add_argument("--max-seconds", type=float, default=None,
                        help="cap on simulated seconds per episode (quick checks)")
    parser.add_argument("--no-scenery", action="store_true", help="road and terrain only")
    parser.add_argument("--out", default="runs/bench", help="output folder")
    parser.add_argument("--json", action="store_true", help="print bench.json's content")
    add_model_arguments(parser)
    add_steering_arguments(parser)


def run(args) -> int:
    from clonedrive.bench.leaderboard import tables
    from clonedrive.bench.run import BenchConfig, bench
    from clonedrive.bench.suite import SuiteError, load_suite
    from clonedrive.data.output_lock import claim_output
    from clonedrive.paths import check_output_folder

    try:
        config = BenchConfig(models=tuple(args.models), suite=args.suite,
                             splits=tuple(args.split or ()), workers=args.workers,
                             ray=args.ray, batch=args.batch, slow_in_curves=args.slow_in_curves,
                             **steering_options(args),
                             scenery=not args.no_scenery, max_seconds=args.max_seconds,
                             offline_data=tuple(args.offline_data or ()),
                             trust_model=args.trust_model, runtime=args.runtime)
        load_suite(config.suite)
        check_output_folder(args.out)
        models = [model.split("=", 1)[-1] for model in args.models]  # LABEL=PATH
        with claim_output("bench", args.out, inputs=models):
            report = bench(config, args.out, progress=not args.json)
    except (SuiteError, ValueError, FileNotFoundError, RuntimeError) as error:
        print(f"clonedrive bench: {error}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    head, rows, _, _ = tables(report)
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    for row in [head, *rows]:
        print("  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)))
    print(f"wrote {args.out}/bench.json, leaderboard.md, leaderboard.html")
    return 0
