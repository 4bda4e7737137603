"""Can the expert drive every episode of a suite clean? (A suite must stay within physics.)

The expert (state only, no cameras: appearance cannot trouble it) drives every episode of the
suite, in its direction, from its start, obeying as late as the episode's latency says, with
the same rules as a model. Prints each split's clean count and every episode that was not
clean; the JSON line's `expert_clean` should equal `episodes`.

Run: python benchmarks/suite_expert.py [--suite v4] [--split NAME ...] [--workers N]
"""

from __future__ import annotations

import argparse
import json
import time


def main() -> int:
    from clonedrive.base.workers import default_workers, run_tasks
    from clonedrive.bench import DEFAULT_SUITE
    from clonedrive.bench.driving import BatchTask, drive_batch
    from clonedrive.bench.suite import load_suite

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", default=DEFAULT_SUITE,
                        help=f"a built-in suite or a suite file (default {DEFAULT_SUITE})")
    parser.add_argument("--split", action="append", default=None,
                        help="drive only this split (repeatable; default every split)")
    parser.add_argument("--workers", type=int, default=default_workers())
    args = parser.parse_args()
    suite = load_suite(args.suite)
    try:
        episodes = suite.episodes(tuple(args.split) if args.split else None)
    except ValueError as error:
        parser.error(str(error))
    tasks = [BatchTask(kind="expert", latency=True, episodes=tuple(episodes[i:i + 8]))
             for i in range(0, len(episodes), 8)]
    started = time.perf_counter()
    results = [run for batch in run_tasks(drive_batch, tasks, workers=args.workers)
               for run in batch]
    wall_s = time.perf_counter() - started
    unclean = [run for run in results if not run["clean"]]
    for split in args.split or suite.split_names():
        runs = [run for run in results if run["split"] == split]
        print(f"{split:<28} expert clean {sum(run['clean'] for run in runs):>3}/{len(runs)}")
    for run in unclean:
        print(f"not clean: {run['key']} {run['track']} {run['speed_mph']:g} mph "
              f"{'reverse' if run['reverse'] else 'forward'} start {run['start_fraction']:g} "
              f"{run['family']}: {run['interventions']} intervention(s)")
    print(f"{len(episodes)} episodes in {wall_s:.0f} s on {args.workers} worker(s)")
    print(json.dumps({"suite": suite.id, "episodes": len(episodes),
                      "expert_clean": len(results) - len(unclean),
                      "unclean": [run["key"] for run in unclean], "wall_s": round(wall_s, 1)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
