"""Which episodes rank models as the full suite does? (How a dev tier is chosen.)

Reads a merged bench.json (the leaderboard's, by default) and, over its models, prints how each
split's mean driving score ranks the models against their mean over every other split (Spearman),
with the spread of the split's means between models: a split every model clears has no spread
and cannot rank. Then a cross-validated check that choosing by this does not just fit the
models at hand: the methods are halved at random (--draws times); on one half the --size
episodes whose score follows the model's mean over the rest most closely (item-rest
correlation, outside the dev tier) are picked, and on the other half their agreement is
measured beside the dev tier's own.

Run: python benchmarks/dev_tier.py [docs/leaderboard/bench.json] [--size 12] [--draws 300]
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def main() -> int:
    from clonedrive.bench.bench_file import BenchFileError, read_bench_file
    from clonedrive.bench.scores import DEV_SPLIT

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bench", nargs="?", default="docs/leaderboard/bench.json")
    parser.add_argument("--size", type=int, default=12, help="episodes a picked tier holds")
    parser.add_argument("--draws", type=int, default=300, help="random halvings of the methods")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    try:
        _, report = read_bench_file(args.bench, args.bench)
    except BenchFileError as error:
        parser.error(str(error))
    if not isinstance(report.get("models"), dict) or len(report["models"]) < 3:
        parser.error(f"{args.bench}: needs a bench run of at least 3 models")
    labels, splits, scores = _score_table(report)
    print(f"{args.bench}: suite {report['suite']['id']}, {len(labels)} models of "
          f"{len(set(labels))} methods, {scores.shape[1]} episodes")
    per_split = {}
    for name in dict.fromkeys(splits):
        inside = splits == name
        rho = _spearman(scores[:, inside].mean(1), scores[:, ~inside].mean(1))
        spread = float(scores[:, inside].mean(1).std())
        per_split[name] = {"spearman": rho, "spread": round(spread, 3)}
        print(f"  {name:<28} {int(inside.sum()):>3} episodes  rank correlation with the rest "
              f"{_text(rho)}  spread of its means {spread:.3f}")
    picked, dev = _cross_validate(labels, splits, scores, DEV_SPLIT, args)
    print(f"cross-validated over {args.draws} halvings of the methods: {args.size} picked "
          f"episodes rank the held-out half at {_text(picked)} (mean Spearman), the dev tier "
          f"at {_text(dev)}")
    print(json.dumps({"models": len(labels), "methods": len(set(labels)),
                      "split_agreement": per_split, "picked_heldout_spearman": picked,
                      "dev_heldout_spearman": dev}))
    return 0


def _score_table(report: dict) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Each model's label, each episode's split and the (models x episodes) driving scores,
    over the episodes every model drove."""
    models = list(report["models"].values())
    table = [{r["key"]: r["scores"]["driving_score"] for r in m["runs"]} for m in models]
    shared = [key for key in table[0] if all(key in row for row in table)]
    scores = np.array([[row[k] for k in shared] for row in table], dtype=float)
    splits = np.array([k.split("/")[0] for k in shared])
    return [m["label"] for m in models], splits, scores


def _cross_validate(labels, splits, scores, dev_split, args) -> tuple[float, float]:
    rng = np.random.default_rng(args.seed)
    methods = sorted(set(labels))
    outside = splits != dev_split
    picked, dev = [], []
    for _ in range(args.draws):
        half = set(rng.permutation(methods)[:len(methods) // 2])
        chooser = np.array([label in half for label in labels])
        held_out = scores[~chooser]
        for tier, out in ((_pick(scores[chooser], outside, args.size), picked), (~outside, dev)):
            rest = outside & ~tier
            out.append(_spearman(held_out[:, tier].mean(1), held_out[:, rest].mean(1)))
    return _mean(picked), _mean(dev)


def _pick(scores: np.ndarray, allowed: np.ndarray, size: int) -> np.ndarray:
    """The ``size`` allowed episodes whose scores correlate most with the models' mean over
    the other allowed episodes."""
    columns = np.flatnonzero(allowed)
    totals = scores[:, allowed].sum(1)
    item_rest = []
    for j in columns:
        column, rest = scores[:, j], (totals - scores[:, j]) / (len(columns) - 1)
        spread = column.std() > 0 and rest.std() > 0
        item_rest.append(np.corrcoef(column, rest)[0, 1] if spread else -1.0)
    chosen = np.zeros(scores.shape[1], dtype=bool)
    chosen[columns[np.argsort(item_rest)[::-1][:size]]] = True
    return chosen


def _spearman(a: np.ndarray, b: np.ndarray) -> float:
    from clonedrive.bench.scores import correlation

    return correlation(list(a), list(b)).get("spearman")


def _mean(values: list) -> float | None:
    kept = [v for v in values if v is not None]
    return round(float(np.mean(kept)), 3) if kept else None


def _text(value: float | None) -> str:
    return "  -  " if value is None else f"{value:.3f}"


if __name__ == "__main__":
    raise SystemExit(main())
