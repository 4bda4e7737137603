"""``clonedrive bench --resume``: go on from the bench.json of an interrupted run.

A bench run rewrites its bench.json as each batch finishes, so a run that was stopped (a closed
terminal, a session's end) has kept every finished batch's runs. Resuming plans the same
batches, takes the runs of the batches whose every episode is there, and drives only the rest.
The batches are cut as before, so each one is driven exactly as the first run would have
driven it, and the resumed bench.json equals an uninterrupted run's.

Only a run made with the same suite, models, settings, renderer and way of predicting
(``prediction``) is resumed; any other bench.json there is refused with the field that differs
(a worker count may differ: it does not change the results).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from clonedrive.bench.driving import BatchTask

#: Settings that do not change what a bench run drives, so may differ when it is resumed.
FREE_SETTINGS = ("workers", "ray")
#: bench.json's fields that must be the same as this run's for its runs to be kept.
MATCHED_FIELDS = ("format", "suite", "settings", "driving", "rendering", "prediction")


class ResumeError(ValueError):
    """The bench.json to resume from is not one of this run; the message says why."""


def previous_report(out: Path, report: dict, defaults: dict) -> dict | None:
    """The bench.json in ``out`` if it is an earlier run of what ``report`` (the new run's
    header) describes; None when ``out`` holds none. ``defaults``: each setting's default,
    for a run made before the setting existed."""
    from clonedrive.base.config import read_json

    path = out / "bench.json"
    if not path.is_file():
        return None
    previous = read_json(path, what="bench.json")
    if not isinstance(previous, dict):
        raise ResumeError(f"{path}: not a bench.json (its top level is not an object)")
    for field in MATCHED_FIELDS:
        if _comparable(field, previous.get(field), defaults) \
                != _comparable(field, report[field], defaults):
            raise ResumeError(f"{path}: its {field!r} differs from this run's, so its runs "
                              f"are not this run's; give the same models and options as it "
                              f"was made with, or another --out")
    return previous


def _comparable(field: str, value: object, defaults: dict) -> object:
    """``value`` of bench.json's ``field`` as compared: without the free settings, and with the
    defaults of settings added since the run was made (what that run drove with)."""
    from clonedrive.network.driving_settings import with_defaults

    if field == "settings" and isinstance(value, dict):
        return {key: item for key, item in {**defaults, **value}.items()
                if key not in FREE_SETTINGS}
    if field == "prediction":
        from clonedrive.bench.bench_file import prediction_of

        return prediction_of({"prediction": value})
    if field == "driving" and isinstance(value, dict):
        return {label: with_defaults(settings) if isinstance(settings, dict) else settings
                for label, settings in value.items()}
    return value


def finished_batches(tasks: list[BatchTask], previous: dict) -> dict[int, list[dict]]:
    """The results, by task index, of the batches ``previous`` holds every run of (each run as
    the worker returned it: without the scores bench.json adds)."""
    reference = previous.get("reference") or {}
    models = previous.get("models") or {}
    finished: dict[int, list[dict]] = {}
    for index, task in enumerate(tasks):
        if task.kind == "expert":
            runs = [reference.get(spec.reference_key) for spec in task.episodes]
        else:
            by_key = {run.get("key"): run for run in
                      (models.get(task.entry) or {}).get("runs", [])}
            runs = [by_key.get(spec.key) for spec in task.episodes]
        if all(isinstance(run, dict) for run in runs):
            finished[index] = [{k: v for k, v in run.items() if k != "scores"} for run in runs]
    return finished
