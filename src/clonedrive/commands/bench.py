"""``clonedrive bench``: drive models through a benchmark suite and write a leaderboard."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from clonedrive.bench import DEFAULT_SUITE, MAX_BATCH
from clonedrive.commands.counts import MAX_WORKERS, count
from clonedrive.commands.model_options import (
    add_model_arguments,
    add_steering_arguments,
    steering_options,
)
from clonedrive.commands.render_options import add_render_arguments, renderer_error

HELP = "drive models through a versioned benchmark suite (splits, conditions) in parallel"
DESCRIPTION = (
    "Drive one or more models through every split of a benchmark suite (built in: v4, the "
    "default, v3 and v2; or a .toml file copied from one): seen tracks, new generated tracks at "
    "three difficulties, held-out conditions, harder tiers at the 30 mph cap. The expert "
    "drives each track and speed cap once as the reference. "
    "Writes bench.json, leaderboard.md and leaderboard.html with plots. Give models as PATH or "
    "LABEL=PATH; models with the same label (one per training seed) are reported as mean +- "
    "std. Every figure carries a 95 % bootstrap interval over episodes (and over a method's "
    "models). Episodes run in batches on --workers processes (default: one per CPU core), or on "
    "Ray with --ray; the results are the same either way. `clonedrive bench compare A B` "
    "compares two bench runs (a folder or bench.json; PATH:LABEL for one method of it, "
    "PATH:LABEL=MODEL for one model) on the "
    "episodes both drove: the difference in each figure with its interval, a permutation-test "
    "p-value, and a sentence saying whether A or B is better; for methods of several models, "
    "the same over training seeds too. `clonedrive bench merge RUN... "
    "--out DIR` merges bench runs of one suite made apart (a split or a model at a time) into "
    "one bench.json and leaderboard (--compact keeps only each run's figures; --suite carries "
    "runs of an earlier suite into a newer one, keeping the splits it defines alike)."
)
#: Example command lines, shown at the end of ``clonedrive bench --help``.
EXAMPLES = (
    "clonedrive bench runs/x/model.keras --out runs/x/bench",
    "clonedrive bench a=runs/a/model.keras b=runs/b/model.keras --split new-tracks-hard",
    "clonedrive bench runs/x/model.keras --out runs/x/bench --resume",
    "clonedrive bench compare runs/a/bench runs/b/bench",
    "clonedrive bench merge runs/x/dev runs/x/hard-30 --out runs/x/bench",
    "clonedrive bench merge runs/v3-run runs/v4-dev --suite v4 --out runs/x/bench",
)


def add_arguments(parser) -> None:
    parser.add_argument("models", nargs="+", metavar="MODEL",
                        help="PATH or LABEL=PATH; or: compare A B (two bench runs); or: "
                             "merge RUN... (bench runs of one suite)")
    parser.add_argument("--suite", default=None,
                        help=f"built-in suite name or a suite .toml (default {DEFAULT_SUITE}); "
                             "merge: carry runs of an earlier suite into this one, keeping the "
                             "splits it defines alike")
    parser.add_argument("--split", action="append", default=None, metavar="NAME",
                        help="run only this split (repeatable)")
    parser.add_argument("--workers", type=count(MAX_WORKERS), default=None, metavar="N",
                        help="worker processes (default: one per CPU core)")
    parser.add_argument("--ray", default=None, metavar="auto|ADDRESS",
                        help="run the batches as Ray tasks (pip install 'clonedrive[cluster]')")
    parser.add_argument("--batch", type=count(MAX_BATCH), default=4,
                        help="episodes one worker drives in lock-step")
    parser.add_argument("--offline-data", action="append", default=None, metavar="DIR",
                        help="held-out recordings: report each model's offline MSE beside its "
                             "closed-loop figures (repeatable)")
    parser.add_argument("--max-seconds", type=float, default=None,
                        help="cap on simulated seconds per episode (quick checks)")
    parser.add_argument("--no-scenery", action="store_true", help="road and terrain only")
    add_render_arguments(parser)
    parser.add_argument("--out", default="runs/bench", help="output folder")
    parser.add_argument("--resume", action="store_true",
                        help="go on from the bench.json an interrupted run of the same models "
                             "and options left in --out: keep its finished batches, drive the "
                             "rest")
    parser.add_argument("--json", action="store_true", help="print bench.json's content")
    parser.add_argument("--compact", action="store_true",
                        help="merge: keep only each run's episode, outcome and scores")
    add_model_arguments(parser)
    add_steering_arguments(parser)


def run(args) -> int:
    if args.models[0] == "compare":
        return _compare(args)
    if args.models[0] == "merge":
        return _merge(args)
    from clonedrive.base.paths import check_output_folder
    from clonedrive.bench.run import BenchConfig, bench
    from clonedrive.bench.suite import SuiteError, load_suite
    from clonedrive.data.output_lock import claim_output

    problem = renderer_error(args, "bench")
    if problem:
        print(problem, file=sys.stderr)
        return 2
    try:
        config = BenchConfig(models=tuple(args.models), suite=args.suite or DEFAULT_SUITE,
                             splits=tuple(args.split or ()), workers=args.workers,
                             ray=args.ray, batch=args.batch,
                             **steering_options(args),
                             scenery=not args.no_scenery, max_seconds=args.max_seconds,
                             offline_data=tuple(args.offline_data or ()),
                             trust_model=args.trust_model, runtime=args.runtime,
                             renderer=args.renderer, full_frame=args.full_frame)
        load_suite(config.suite)
        check_output_folder(args.out)
        models = [model.split("=", 1)[-1] for model in args.models]  # LABEL=PATH
        with claim_output("bench", args.out, inputs=models):
            report = bench(config, args.out, progress=not args.json, resume=args.resume)
    except (SuiteError, ValueError, FileNotFoundError, RuntimeError) as error:
        print(f"clonedrive bench: {error}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    _print_methods(report)
    print(f"wrote {args.out}/bench.json, leaderboard.md, leaderboard.html")
    return 0


def _print_methods(report: dict) -> None:
    from clonedrive.bench.leaderboard import methods_text

    print(methods_text(report))


def _merge(args) -> int:
    """``bench merge RUN... --out DIR``: one bench.json and leaderboard from several runs."""
    from clonedrive.base.config import write_json_atomic, write_text_atomic
    from clonedrive.base.paths import check_output_folder
    from clonedrive.bench.leaderboard import write_leaderboard
    from clonedrive.bench.merge import MergeError, load_bench_run, merge_reports
    from clonedrive.bench.suite import SuiteError, load_suite

    if len(args.models) < 2:
        print("clonedrive bench: merge takes bench runs: merge RUN... --out DIR",
              file=sys.stderr)
        return 2
    try:
        suite = load_suite(args.suite).to_dict() if args.suite else None
        named = [(spec, load_bench_run(spec)) for spec in args.models[1:]]
        report = merge_reports(named, compact=args.compact, suite=suite)
        check_output_folder(args.out)
        Path(args.out).mkdir(parents=True, exist_ok=True)
        if args.compact:  # for keeping in a repository: one line, no indentation
            write_text_atomic(Path(args.out) / "bench.json",
                              json.dumps(report, separators=(",", ":")) + "\n")
        else:
            write_json_atomic(Path(args.out) / "bench.json", report)
        write_leaderboard(report, args.out)
    except (MergeError, SuiteError, OSError, ValueError) as error:
        print(f"clonedrive bench: {error}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    _print_methods(report)
    for name, splits in report["settings"].get("left_out", {}).items():
        print(f"{name}: left out split(s) {', '.join(splits)} (suite {report['suite']['id']} "
              "defines them otherwise)")
    print(f"merged {len(named)} bench run(s); wrote {args.out}/bench.json, leaderboard.md, "
          "leaderboard.html")
    return 0


def _compare(args) -> int:
    """``bench compare A B``: print each figure's paired comparison (or the JSON)."""
    from clonedrive.bench.compare import CompareError, compare

    if len(args.models) != 3:
        print("clonedrive bench: compare takes two bench runs: compare A B", file=sys.stderr)
        return 2
    try:
        result = compare(args.models[1], args.models[2])
    except (CompareError, OSError, ValueError) as error:
        print(f"clonedrive bench: {error}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"A = {result['a']}, B = {result['b']}, suite {result['suite']}")
    if result.get("caveat"):
        print(f"note: {result['caveat']}")
    for item in result["comparisons"]:
        _print_comparison(item, f"over {item['episodes']} episodes", "")
    for item in result.get("over_seeds", []):
        models = "{} against {} models".format(*item["models"])
        means = (f"; models' means A {item.get('a_model_means')}, "
                 f"B {item.get('b_model_means')}")
        _print_comparison(item, f"over seeds ({models})", means)
    return 0


def _print_comparison(item: dict, scope: str, extra: str) -> None:
    """One figure's comparison: the difference with its interval (when there is one), then the
    sentence."""
    if item["difference"] is not None:
        print(f"  {item['figure']} {scope}: A - B = {item['difference']:+.4g} "
              f"[{item['low']:+.4g}, {item['high']:+.4g}]{extra}")
    print(f"    {item['sentence']}")
