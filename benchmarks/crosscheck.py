"""Open-loop figures of several models on real Udacity frames, side by side (issue 15).

For each model and each log, ``clonedrive.evaluate.crosscheck``: RMSE against the human's
steering beside the always-0 and always-the-mean baselines, and the correlation with the
human's steering smoothed over 5 frames. Default logs: the two real slices in
``tests/fixtures/udacity`` (70 rows each, lake and mountain); give others as arguments.

Run: python benchmarks/crosscheck.py --model sim=runs/a/model.keras --model real=runs/b/model.keras
     [LOG_DIR ...] [--trust-model]
Ends with one JSON line: {"models": {label: {log: {rows, rmse, rmse_zero, rmse_mean,
correlation, correlation_raw}}}, "mean_correlation": {label: ...}}.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from clonedrive.drivers.policy import load_policy
from clonedrive.evaluate.crosscheck import crosscheck

FIXTURES = Path(__file__).parents[1] / "tests" / "fixtures" / "udacity"
DEFAULT_LOGS = (FIXTURES / "lake_posix_mixed_columns", FIXTURES / "mountain_windows_paths")
KEYS = ("rows", "rmse", "rmse_zero", "rmse_mean", "correlation", "correlation_raw")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="*", type=Path, default=list(DEFAULT_LOGS))
    parser.add_argument("--model", action="append", required=True, metavar="LABEL=PATH")
    parser.add_argument("--trust-model", action="store_true")
    args = parser.parse_args()

    results: dict[str, dict[str, dict]] = {}
    with tempfile.TemporaryDirectory(prefix="crosscheck-") as scratch:
        for entry in args.model:
            label, _, path = entry.partition("=")
            if not path:
                label, path = Path(entry).stem, entry
            policy = load_policy(path, trust=args.trust_model)
            results[label] = {}
            for log in args.logs:
                report = crosscheck(policy, log, Path(scratch) / label / log.name,
                                    model_path=path)
                results[label][log.name] = {key: report[key] for key in KEYS}

    logs = [log.name for log in args.logs]
    width = max(len(label) for label in results) + 2
    print(f"{'model':<{width}}" + "".join(f"{log[:28]:>32}" for log in logs))
    print(f"{'':<{width}}" + "".join(f"{'r    RMSE (0 / mean)':>32}" for _ in logs))
    for label, per_log in results.items():
        cells = []
        for log in logs:
            item = per_log[log]
            r = "n/a" if item["correlation"] is None else f"{item['correlation']:+.2f}"
            cells.append(f"{r}  {item['rmse']:.3f} ({item['rmse_zero']:.3f} / "
                         f"{item['rmse_mean']:.3f})")
        print(f"{label:<{width}}" + "".join(f"{cell:>32}" for cell in cells))
    mean_r = {}
    for label, per_log in results.items():
        values = [item["correlation"] for item in per_log.values()
                  if item["correlation"] is not None]
        mean_r[label] = round(sum(values) / len(values), 4) if values else None
    print(json.dumps({"models": results, "mean_correlation": mean_r}))


if __name__ == "__main__":
    main()
