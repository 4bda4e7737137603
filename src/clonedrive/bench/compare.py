"""``clonedrive bench compare A B``: two methods on the same episodes, with confidence.

A and B each name a bench run (a folder holding ``bench.json``, or the file) and optionally one
of its methods (``PATH:LABEL``; without a label the run must hold one method) or one of its
models (``PATH:ENTRY``, the model's key in bench.json, e.g. ``a=runs/a0/model.keras``). A
method's value on an episode is the mean over its models (its training seeds) on that episode;
episodes pair by the suite's episode key (``split/index``), so both runs must come from the
same suite. Each figure's comparison is :func:`clonedrive.bench.stats.paired_comparison`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

#: (figure, per-run value, higher is better) of a comparison, in the order reported.
FIGURES: tuple[tuple[str, Callable[[dict], float | None], bool], ...] = (
    ("driving score", lambda run: run["scores"]["driving_score"], True),
    ("success %", lambda run: 100.0 * bool(run["scores"]["clean"]), True),
    ("interventions per km", lambda run: run["scores"]["interventions_per_km"], False),
    ("lap time ratio", lambda run: run["scores"]["lap_time_ratio"], False),
)


class CompareError(ValueError):
    """A bench run or method that cannot be compared; the message says which and why."""


def load_method(spec: str) -> tuple[str, dict, list[list[dict]], str]:
    """``PATH[:LABEL]`` -> (a name for it, its suite, the runs of each model of the method, how
    its policy predicted: :func:`clonedrive.bench.bench_file.prediction_of`)."""
    from clonedrive.bench.bench_file import prediction_of, read_bench_file

    path_text, _, label = spec.rpartition(":") if not Path(spec).exists() else (spec, "", "")
    if not path_text:
        path_text, label = label, ""
    path, report = read_bench_file(path_text, spec)
    methods = report.get("methods")
    if not isinstance(methods, dict) or not methods:
        raise CompareError(f"{path}: not a bench.json with methods")
    if not label:
        if len(methods) != 1:
            raise CompareError(f"{path} holds {len(methods)} methods "
                               f"({', '.join(sorted(methods))}): name one as PATH:LABEL")
        label = next(iter(methods))
    if label in methods:
        models = [report["models"][entry] for entry in methods[label]["models"]]
    elif label in report.get("models", {}):  # one model of a method: one training seed
        models = [report["models"][label]]
    else:
        raise CompareError(f"{path}: no method {label!r} (it has {', '.join(sorted(methods))})")
    return (f"{label} ({path.parent.name})", report.get("suite", {}),
            [list(model.get("runs", [])) for model in models], prediction_of(report))


def per_episode(runs: list[dict], value: Callable[[dict], float | None]) -> dict[str, float]:
    """Episode key -> the mean over the method's models of ``value`` (episodes where no model
    has a value are left out)."""
    by_key: dict[str, list[float]] = {}
    for run in runs:
        figure = value(run)
        if figure is not None:
            by_key.setdefault(run["key"], []).append(float(figure))
    return {key: float(np.mean(values)) for key, values in by_key.items()}


def compare(spec_a: str, spec_b: str, *, seed: int = 0) -> dict:
    """Every figure of :data:`FIGURES` compared between the methods ``spec_a`` and ``spec_b``."""
    from clonedrive.bench.stats import paired_comparison, seed_comparison

    name_a, suite_a, models_a, prediction_a = load_method(spec_a)
    name_b, suite_b, models_b, prediction_b = load_method(spec_b)
    if suite_a.get("id") != suite_b.get("id"):
        raise CompareError(f"different suites ({suite_a.get('id')} and {suite_b.get('id')}): "
                           "their episodes do not pair")
    runs_a = [run for runs in models_a for run in runs]
    runs_b = [run for runs in models_b for run in runs]
    names = (name_a, name_b)
    results = [paired_comparison(per_episode(runs_a, value), per_episode(runs_b, value),
                                 figure=figure, higher_is_better=higher, names=names, seed=seed)
               for figure, value, higher in FIGURES]
    result = {"a": name_a, "b": name_b, "suite": suite_a.get("id"), "comparisons": results}
    if prediction_a != prediction_b:
        result["caveat"] = (
            f"A and B did not predict alike (A: {prediction_a}; B: {prediction_b}): each "
            "prediction then differs by its last bits, which the closed loop makes a slightly "
            "different path (as between machines), so part of a small difference may be that")
    if max(len(models_a), len(models_b)) > 1:  # a recipe's seeds: does the difference hold?
        result["over_seeds"] = [
            seed_comparison([per_episode(runs, value) for runs in models_a],
                            [per_episode(runs, value) for runs in models_b], figure=figure,
                            higher_is_better=higher, names=names, seed=seed)
            for figure, value, higher in FIGURES]
    return result
