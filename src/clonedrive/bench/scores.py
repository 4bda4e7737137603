"""Benchmark figures (DESIGN.md, "Benchmark figures"): per run, per split, per method.

Per run (one episode of one model), against the expert's reference lap on the same track and
speed cap: **clean** (every lap without a tyre off the road), **interventions per km**,
**autonomy %**, **mean |CTE|**, **lap-time ratio** (a clean lap's time / the expert's; lower is
faster), **smoothness ratio** (mean |steering change| per second / the expert's).

Per split: success % (share of clean runs), interventions per km (all interventions / all km),
mean autonomy %, mean |CTE|, mean lap-time ratio over the clean runs, mean smoothness ratio.

Per method (models given the same label, e.g. one per training seed): each split figure as
mean +- standard deviation over its models (sample std, n - 1).

Offline against closed loop: Pearson and Spearman correlation, over models, of the offline
validation MSE with the overall success % and interventions per km (Codevilla et al. 2018 found
offline error a poor predictor of driving).

The dev tier against the rest: over models that drove the :data:`DEV_SPLIT` and other splits,
the correlation of their dev driving score with their driving score on every other episode
(how well the quick tier ranks models as the full suite does).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

SPLIT_FIGURES = ("success_pct", "interventions_per_km", "autonomy_pct", "mean_abs_cte_m",
                 "lap_time_ratio", "smoothness_ratio", "driving_score")
#: The driving score's factor per intervention (CARLA-style: completion x penalties).
INTERVENTION_PENALTY = 0.7
#: The name of a suite's quick tier, whose ranking of models is checked against the rest.
DEV_SPLIT = "dev"


def driving_score(run: dict) -> float:
    """Route completion (distance driven / the episode's route, at most 1; a run without a
    route length counts 1 if clean, else 0) times :data:`INTERVENTION_PENALTY` per
    intervention: 1.0 is the whole route without leaving the road."""
    route = run.get("route_m")
    if route:
        completion = min(1.0, float(run["distance_m"]) / float(route))
    else:
        completion = 1.0 if run["clean"] else 0.0
    return round(completion * INTERVENTION_PENALTY ** int(run["interventions"]), 4)


def run_scores(run: dict, reference: dict | None) -> dict:
    """The figures of one run next to its expert reference (None: no reference)."""
    km = run["distance_m"] / 1000.0
    scores = {
        "clean": bool(run["clean"]),
        "interventions_per_km": round(run["interventions"] / km, 3) if km > 0 else None,
        "autonomy_pct": run["autonomy_pct"],
        "mean_abs_cte_m": run["mean_abs_cte_m"],
        "lap_time_ratio": None,
        "smoothness_ratio": None,
        "driving_score": driving_score(run),
    }
    if reference is not None:
        if run.get("lap_time_s") and reference.get("lap_time_s"):
            scores["lap_time_ratio"] = round(run["lap_time_s"] / reference["lap_time_s"], 4)
        if reference.get("smoothness"):
            scores["smoothness_ratio"] = round(run["smoothness"] / reference["smoothness"], 4)
    return scores


def _mean(values: Sequence[float | None]) -> float | None:
    kept = [v for v in values if v is not None]
    return round(float(np.mean(kept)), 4) if kept else None


def split_scores(runs: Sequence[dict]) -> dict:
    """Figures of a split from its runs (each run: its result with ``scores``)."""
    km = sum(run["distance_m"] for run in runs) / 1000.0
    clean = [run for run in runs if run["scores"]["clean"]]
    return {
        "runs": len(runs),
        "clean_runs": len(clean),
        "success_pct": round(100.0 * len(clean) / len(runs), 2) if runs else None,
        "interventions_per_km": round(sum(r["interventions"] for r in runs) / km, 3)
        if km > 0 else None,
        "autonomy_pct": _mean([r["scores"]["autonomy_pct"] for r in runs]),
        "mean_abs_cte_m": _mean([r["scores"]["mean_abs_cte_m"] for r in runs]),
        "lap_time_ratio": _mean([r["scores"]["lap_time_ratio"] for r in clean]),
        "smoothness_ratio": _mean([r["scores"]["smoothness_ratio"] for r in runs]),
        "driving_score": _mean([r["scores"]["driving_score"] for r in runs]),
        "ci": split_intervals(runs),
    }


def split_intervals(runs: Sequence[dict]) -> dict:
    """95 % bootstrap intervals over a split's episodes: success %, interventions per km
    (pooled), driving score (:mod:`clonedrive.bench.stats`)."""
    from clonedrive.bench.stats import bootstrap_ci, ratio_ci

    return {
        "success_pct": bootstrap_ci([100.0 * bool(r["scores"]["clean"]) for r in runs]),
        "interventions_per_km": ratio_ci([r["interventions"] for r in runs],
                                         [r["distance_m"] / 1000.0 for r in runs]),
        "driving_score": bootstrap_ci([r["scores"]["driving_score"] for r in runs]),
    }


def method_scores(models: Sequence[dict], split_names: Sequence[str]) -> dict:
    """Per split and figure: mean, std (n - 1; None for one model) and n over ``models`` (each
    with ``splits`` and ``overall`` as :func:`split_scores` gives them)."""
    out = {}
    for split in [*split_names, "overall"]:
        figures = {}
        for figure in SPLIT_FIGURES:
            values = [m["splits"][split][figure] if split != "overall" else m["overall"][figure]
                      for m in models]
            values = [v for v in values if v is not None]
            if not values:
                figures[figure] = {"mean": None, "std": None, "n": 0}
                continue
            std = float(np.std(values, ddof=1)) if len(values) > 1 else None
            figures[figure] = {"mean": round(float(np.mean(values)), 4),
                               "std": None if std is None else round(std, 4), "n": len(values)}
        out[split] = figures
    return out


def method_intervals(models: Sequence[dict], split_names: Sequence[str]) -> dict:
    """Per split (and overall): 95 % intervals of a method's success % and driving score from
    a hierarchical bootstrap over its models (training seeds) and their episodes."""
    from clonedrive.bench.stats import hierarchical_ci

    out = {}
    for split in [*split_names, "overall"]:
        groups = [[r for r in m["runs"] if split == "overall" or r["split"] == split]
                  for m in models]
        out[split] = {
            "success_pct": hierarchical_ci([[100.0 * bool(r["scores"]["clean"]) for r in g]
                                            for g in groups]),
            "driving_score": hierarchical_ci([[r["scores"]["driving_score"] for r in g]
                                              for g in groups]),
        }
    return out


def _ranks(values: np.ndarray) -> np.ndarray:
    order = np.argsort(values, kind="stable")
    ranks = np.empty(len(values))
    ranks[order] = np.arange(len(values), dtype=float)
    for value in np.unique(values):  # ties share their mean rank
        tied = values == value
        ranks[tied] = ranks[tied].mean()
    return ranks


def correlation(x: Sequence[float], y: Sequence[float]) -> dict:
    """Pearson and Spearman correlation of paired values (None where undefined: fewer than 3
    pairs, or a constant series)."""
    pairs = [(a, b) for a, b in zip(x, y, strict=True) if a is not None and b is not None]
    out = {"n": len(pairs), "pearson": None, "spearman": None}
    if len(pairs) < 3:
        return out
    a, b = (np.asarray(v, dtype=float) for v in zip(*pairs, strict=True))
    for name, (u, v) in (("pearson", (a, b)), ("spearman", (_ranks(a), _ranks(b)))):
        if np.std(u) > 0 and np.std(v) > 0:
            r = float(np.corrcoef(u, v)[0, 1])
            out[name] = round(r, 4) if math.isfinite(r) else None
    return out


def dev_agreement(models: dict[str, dict]) -> dict | None:
    """How the :data:`DEV_SPLIT` ranks ``models`` against all their other episodes: the
    correlation (over models) of the dev tier's mean driving score with the mean driving score
    of the rest, and of their success %. None unless at least two models drove both."""
    dev, rest, dev_success, rest_success = [], [], [], []
    for model in models.values():
        inside = [r["scores"] for r in model["runs"] if r["split"] == DEV_SPLIT]
        outside = [r["scores"] for r in model["runs"] if r["split"] != DEV_SPLIT]
        if not inside or not outside:
            continue
        dev.append(_mean([s["driving_score"] for s in inside]))
        rest.append(_mean([s["driving_score"] for s in outside]))
        dev_success.append(100.0 * float(np.mean([s["clean"] for s in inside])))
        rest_success.append(100.0 * float(np.mean([s["clean"] for s in outside])))
    if len(dev) < 2:
        return None
    return {"models": len(dev), "driving_score": correlation(dev, rest),
            "success_pct": correlation(dev_success, rest_success)}


def offline_correlations(models: Sequence[dict]) -> dict:
    """Over ``models`` (each with ``offline_mse`` and ``overall`` figures): the correlation of
    the offline MSE with success %, interventions per km and the driving score."""
    mse = [m["offline_mse"] for m in models]
    return {f"vs_{figure}": correlation(mse, [m["overall"].get(figure) for m in models])
            for figure in ("success_pct", "interventions_per_km", "driving_score")}
