"""``clonedrive bench merge``: bench runs of one suite, made apart, as one bench run.

A full suite for several models takes hours on a small machine; it can be run a split or a
model at a time, on one machine or several, and merged. The merged bench.json holds every
model's runs from every input, its figures recomputed over all of them (per split, overall, per
method with the hierarchical intervals), the expert references, the offline MSE where an input
measured it, and the dev tier's agreement with the rest
(:func:`clonedrive.bench.scores.dev_agreement`).

Inputs must come from the same suite id and the same renderer (frames differ slightly between
renderers), and no model may have driven one episode twice. Given a ``suite``, runs of an
earlier version are carried into it (:func:`carry_into`): a split it defines alike keeps its
runs, so a new suite version that changes one split need not drive the others again. Each
model's runs are put in the suite's order, so the intervals do not depend on the order of the
inputs. ``compact`` keeps of each run only what the figures and ``bench compare`` need, for
results kept in a repository.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from clonedrive.bench.run import BENCH_FORMAT, summarize
from clonedrive.bench.scores import dev_agreement, offline_correlations
from clonedrive.network.driving_settings import with_defaults

#: What a compacted run keeps: its episode, what its split's figures are pooled from, and its
#: scores (no traces, no conditions); :func:`clonedrive.bench.scores.split_scores` and
#: ``bench compare`` need no more.
COMPACT_RUN_FIELDS = ("key", "split", "track", "interventions", "distance_m", "scores")


class MergeError(ValueError):
    """Bench runs that cannot be merged; the message names the run and why."""


def load_bench_run(spec: str) -> dict:
    """A finished bench run's bench.json (``spec``: its folder or the file, or ``LABEL=`` and
    either: every model of the run is then labelled ``LABEL``, one method)."""
    from clonedrive.bench.bench_file import read_bench_file

    label, _, path_text = spec.rpartition("=") if not Path(spec).exists() else ("", "", spec)
    path, report = read_bench_file(path_text, spec)
    if not isinstance(report.get("models"), dict):
        raise MergeError(f"{path}: not a bench.json with models")
    if not report.get("complete"):
        raise MergeError(f"{path}: an unfinished bench run (its \"complete\" is not true)")
    if label:
        settings = list(report.get("driving", {}).values())
        if any(other != settings[0] for other in settings[1:]):
            raise MergeError(f"{path}: its models drive with different settings, so they "
                             f"cannot be one method {label!r}")
        for model in report["models"].values():
            model["label"] = label
        report["driving"] = {label: settings[0] if settings else {}}
    return report


def carry_into(report: dict, suite: dict) -> tuple[dict, list[str]]:
    """``report`` (a bench.json's content) as a run of ``suite`` (a suite's ``to_dict()``): the
    runs of each split that ``suite`` defines alike (the same episodes: tracks, speeds,
    directions, starts, conditions with their families' values, seed and laps), none of the
    others. Returns the carried report and the names of the splits left out."""
    if report.get("suite", {}).get("id") == suite["id"]:
        return report, []
    kept = {name for name in _suite_splits(report)
            if _episodes_of(report["suite"], name) == _episodes_of(suite, name)}
    models = {entry: {**model, "runs": [run for run in model.get("runs", [])
                                        if run["split"] in kept]}
              for entry, model in report["models"].items()}
    carried = {**report, "suite": suite,  # a model left with no runs is left out too
               "models": {entry: model for entry, model in models.items() if model["runs"]}}
    return carried, [name for name in _suite_splits(report) if name not in kept]


def _episodes_of(suite: dict, split_name: str) -> tuple | None:
    """What decides a split's episodes in a suite's ``to_dict()`` (descriptions aside)."""
    split = next((s for s in suite.get("splits", []) if s["name"] == split_name), None)
    if split is None:
        return None
    families = suite.get("conditions", {})
    return (suite.get("laps"), _without_description(split),
            [_without_description(families.get(name, {})) for name in split["conditions"]])


def _without_description(table: dict) -> dict:
    return {key: value for key, value in table.items() if key != "description"}


def merge_reports(named: Sequence[tuple[str, dict]], *, compact: bool = False,
                  suite: dict | None = None) -> dict:
    """One bench report from ``(name, bench.json content)`` pairs of one suite (or, given
    ``suite``, carried into it by :func:`carry_into`; ``settings.left_out`` then names each
    input's splits that suite defines otherwise)."""
    if not named:
        raise MergeError("nothing to merge")
    left_out: dict[str, list[str]] = {}  # what earlier merges left out too
    for _, report in named:
        left_out.update((report.get("settings") or {}).get("left_out") or {})
    if suite is not None:
        carried = []
        for name, report in named:
            report, dropped = carry_into(report, suite)
            carried.append((name, report))
            if dropped:
                left_out[name] = dropped
        named = carried
        if not any(report["models"] for _, report in named):
            raise MergeError(f"suite {suite['id']} defines every split of the runs otherwise: "
                             "nothing to carry into it")
    first_name, first = named[0]
    for name, report in named[1:]:
        _check_same(first_name, first, name, report)
    models: dict[str, dict] = {}
    reference: dict[str, dict] = {}
    offline = None
    for name, report in named:
        reference.update(report.get("reference", {}))
        if report.get("offline"):
            if offline and offline.get("data") != report["offline"].get("data"):
                raise MergeError(f"{name}: its offline MSE is on other held-out data than "
                                 "another run's")
            offline = report["offline"]
        for entry, model in report["models"].items():
            _add_model(models, entry, model, name, compact)
    splits = {run["split"] for model in models.values() for run in model["runs"]}
    lists = sorted((_suite_splits(report) for _, report in named), key=len, reverse=True)
    order = [s for names in lists for s in names]  # the fullest suite's order first
    split_names = [s for s in dict.fromkeys(order) if s in splits]
    position = {name: i for i, name in enumerate(split_names)}
    for model in models.values():  # the same merged figures whatever the inputs' order
        model["runs"].sort(key=lambda run: (position[run["split"]], run["key"]))
    methods = summarize(models, split_names)
    merged = {
        "format": BENCH_FORMAT, "suite": first["suite"],
        "settings": {"merged_from": [source for name, report in named
                                     for source in _sources(name, report)]},
        "speed_control": first.get("speed_control") or "as each input run says",
        "driving": _driving(named),
        "rendering": first.get("rendering"), "prediction": _prediction(named),
        "complete": True,
        "reference": {} if compact else reference, "models": models, "methods": methods,
        "split_names": split_names, "dev_agreement": dev_agreement(models),
    }
    if left_out:
        merged["settings"]["left_out"] = left_out
    if offline and all("offline_mse" in m for m in models.values()):
        merged["offline"] = _offline(offline, models)
    return merged


def _driving(named: Sequence[tuple[str, dict]]) -> dict[str, dict]:
    """Each method's driving settings, which must be the same in every run it is in."""
    driving: dict[str, dict] = {}
    for name, report in named:
        for label, given in report.get("driving", {}).items():
            settings = with_defaults(given)
            if driving.setdefault(label, settings) != settings:
                raise MergeError(f"{name}: method {label!r} drives with other settings there "
                                 f"({settings}) than in another run ({driving[label]})")
    return driving


def _prediction(named: Sequence[tuple[str, dict]]) -> str:
    """How the inputs' policies predicted: one way, or each way named (``bench compare`` then
    says the runs were not all driven alike)."""
    from clonedrive.bench.bench_file import prediction_of

    ways = list(dict.fromkeys(prediction_of(report) for _, report in named))
    return ways[0] if len(ways) == 1 else "mixed: " + "; ".join(ways)


def _sources(name: str, report: dict) -> list[str]:
    """The runs a report was made from: itself, or what it was merged from."""
    return list((report.get("settings") or {}).get("merged_from") or [name])


def _suite_splits(report: dict) -> list[str]:
    return [split["name"] for split in report["suite"].get("splits", [])]


def _check_same(first_name: str, first: dict, name: str, report: dict) -> None:
    suite_a, suite_b = first.get("suite", {}).get("id"), report.get("suite", {}).get("id")
    if suite_a != suite_b:
        raise MergeError(f"{name} is of suite {suite_b}, {first_name} of {suite_a}: "
                         "their episodes are not the same")
    used_a = (first.get("rendering") or {}).get("renderer_used")
    used_b = (report.get("rendering") or {}).get("renderer_used")
    if used_a != used_b:
        raise MergeError(f"{name} was drawn by the {used_b} renderer, {first_name} by "
                         f"{used_a}: frames differ between renderers")


def _add_model(models: dict, entry: str, model: dict, source: str, compact: bool) -> None:
    merged = models.setdefault(entry, {"label": model["label"], "path": model["path"],
                                       "runs": []})
    if merged["label"] != model["label"]:
        raise MergeError(f"{source}: model {model['path']} is labelled {model['label']!r} "
                         f"there and {merged['label']!r} in another run")
    seen = {run["key"] for run in merged["runs"]}
    for run in model.get("runs", []):
        if run["key"] in seen:
            raise MergeError(f"{source}: model {entry} drove episode {run['key']} in another "
                             "run too")
        merged["runs"].append({k: run[k] for k in COMPACT_RUN_FIELDS if k in run}
                              if compact else run)
    if "offline_mse" in model:
        merged["offline_mse"] = model["offline_mse"]


def _offline(offline: dict, models: dict) -> dict:
    return {"data": offline.get("data"), "rows": offline.get("rows"),
            **offline_correlations(list(models.values()))}
