"""The leaderboard of baselines: make a row's model for one training seed, drive it through the
full suite, and merge its results into the repository's leaderboard (docs/leaderboard/).

    python benchmarks/leaderboard.py list
    python benchmarks/leaderboard.py commands writeup --seed 1
    python benchmarks/leaderboard.py run writeup --seed 1 [--runs runs/leaderboard]

``run`` skips a command whose ``--out`` exists (a row's run folder or model, the held-out
recordings, the bench run): rows share their steps, and a stopped row goes on from the first
command not made (remove a half-made output to make it again). The rows, their commands and
the suite are in benchmarks/leaderboard/baselines.toml. The last line printed is one JSON
object.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINES = ROOT / "benchmarks" / "leaderboard" / "baselines.toml"
BOARD = "docs/leaderboard"  #: the repository's leaderboard, relative to ROOT
DEFAULT_RUNS = "runs/leaderboard"
ENSEMBLE_SIZE = 3  #: models in an ensemble row's model ({members[0]} to {members[2]})


def load_rows() -> tuple[dict, dict[str, dict]]:
    table = tomllib.loads(BASELINES.read_text(encoding="utf-8"))
    return table, {row["name"]: row for row in table["baseline"]}


def members(seed: int) -> tuple[int, ...]:
    """The ``best`` seeds an ensemble of training seed ``seed`` is made of: seed 0 is the mean
    of best's seeds 0-2, seed 1 of seeds 3-5, and so on, so no two ensembles share a model."""
    return tuple(range(ENSEMBLE_SIZE * seed, ENSEMBLE_SIZE * (seed + 1)))


def fill(text: str, row: dict, seed: int, runs: str) -> str:
    names = {"seed": seed, "runs": runs, "members": members(seed)}
    return text.format(**names, row=row["name"], model=row["model"].format(**names))


def made_by(command: str) -> str:
    """The file or folder a command writes: its ``--out``."""
    return command.split("--out ")[-1].split()[0]


def row_steps(table: dict, rows: dict[str, dict], name: str, seed: int, runs: str) -> list[str]:
    """The commands of a row and of the rows it follows, in order."""
    row = rows[name]
    steps = row_steps(table, rows, row["after"], seed, runs) if "after" in row else []
    return steps + [fill(command, row, seed, runs) for command in row["commands"]]


def bench_steps(table: dict, row: dict, seed: int, runs: str) -> list[str]:
    """The held-out recordings, the row's bench run on the full suite, and the merge of its
    results into the repository's leaderboard."""
    heldout = [command.format(runs=runs) for command in table["heldout"]]
    data = " ".join(f"--offline-data {made_by(command)}" for command in heldout)
    model = fill(row["model"], row, seed, runs)
    out = f"{runs}/bench/{row['name']}-s{seed}"
    drive = f" {row['drive']}" if row.get("drive") else ""
    bench = (f"clonedrive bench {row['name']}={model} --suite {table['suite']}{drive} {data} "
             f"--out {out}")
    inputs = [BOARD] if (ROOT / BOARD / "bench.json").is_file() else []
    inputs.append(f"{row['name']}={out}")
    merge = f"clonedrive bench merge {' '.join(inputs)} --compact --out {BOARD}"
    return [*heldout, bench, merge]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="example: python benchmarks/leaderboard.py run "
                                            "center --seed 0")
    parser.add_argument("action", choices=("list", "commands", "run"))
    parser.add_argument("row", nargs="?")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--runs", default=DEFAULT_RUNS, help="where models and bench runs go")
    args = parser.parse_args(argv)
    table, rows = load_rows()
    if args.action == "list":
        for name, row in rows.items():
            print(f"{name}: {row['summary']}")
        print(json.dumps({"rows": list(rows), "suite": table["suite"]}))
        return 0
    if args.row not in rows:
        parser.error(f"name a row: {', '.join(rows)}")
    steps = (row_steps(table, rows, args.row, args.seed, args.runs)
             + bench_steps(table, rows[args.row], args.seed, args.runs))
    ran = []
    for command in steps:
        if args.action == "commands":
            print(command)
            continue
        if " merge " not in command and (ROOT / made_by(command)).exists():
            print(f"exists, skipped: {command}")
            continue
        print(f"running: {command}", flush=True)
        code = subprocess.run(shlex.split(command), cwd=ROOT).returncode
        if code:
            print(f"stopped: that step failed (exit status {code}); the steps before it are "
                  "kept and are skipped when the row is run again", file=sys.stderr)
            return code
        ran.append(command)
    print(json.dumps({"row": args.row, "seed": args.seed, "steps": len(steps),
                      "ran": len(ran)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
