"""The repository's leaderboard in brief, shipped inside the package: each method's mean figures
per split, so that a report made anywhere (a wheel, no repository) can set a run's own bench
beside the board's methods.

The figures come from the leaderboard's ``bench.json`` (``docs/leaderboard/`` in the
repository); after ``bench merge`` changes the board, write the brief again with::

    python -m clonedrive.bench.board docs/leaderboard/bench.json

A test checks that the shipped brief is the board's.
"""

from __future__ import annotations

import json
import sys
from importlib import resources
from pathlib import Path

#: The brief's file name in this package.
BOARD_FILE = "board.json"
#: The figures the brief keeps of each method and split (means over the method's models).
FIGURES = ("success_pct", "driving_score", "lap_time_ratio", "smoothness_ratio")


def board_brief(report: dict) -> dict:
    """``{"suite": id, "methods": {method: {split: {figure: mean, "models": n}}}}`` of a
    leaderboard's bench.json content ``report``."""
    methods = {}
    for label, method in (report.get("methods") or {}).items():
        splits = {}
        for split, scores in (method.get("scores") or {}).items():
            if split == "overall" or not isinstance(scores, dict):
                continue
            figures = {name: (scores.get(name) or {}).get("mean") for name in FIGURES}
            figures["models"] = (scores.get("success_pct") or {}).get("n")
            splits[split] = figures
        methods[label] = splits
    return {"suite": (report.get("suite") or {}).get("id"), "methods": methods}


def shipped_board() -> dict:
    """The brief shipped with this package (``{}`` when there is none)."""
    source = resources.files(__package__).joinpath(BOARD_FILE)
    if not source.is_file():
        return {}
    return json.loads(source.read_text(encoding="utf-8"))


def board_text(report: dict) -> str:
    """The brief of ``report`` as the shipped file holds it."""
    return json.dumps(board_brief(report), indent=1, sort_keys=True) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write the brief of the leaderboard bench.json given as the one argument."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m clonedrive.bench.board docs/leaderboard/bench.json",
              file=sys.stderr)
        return 2
    report = json.loads(Path(args[0]).read_text(encoding="utf-8"))
    target = Path(__file__).with_name(BOARD_FILE)
    target.write_text(board_text(report), encoding="utf-8")
    print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
