"""The whole DAgger run: iteration 0 (the base model), then collect, aggregate, retrain and
measure per iteration, and plain cloning with as many labels; ``dagger.json`` after each."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path

from clonedrive.base.config import changed_settings, config_to_dict, read_json, write_json_atomic
from clonedrive.pipelines.dagger.config import (
    DAGGER_JSON,
    DAGGER_PNG,
    RERUN_MAY_CHANGE,
    DaggerConfig,
)
from clonedrive.pipelines.dagger.figures import plot_dagger
from clonedrive.pipelines.dagger.measure import evaluate_model, expert_references
from clonedrive.pipelines.dagger.stages import (
    aggregate_recipe,
    check_human_recordings,
    collect,
    record_plain,
    retrain,
)


def run_dagger(config: DaggerConfig, base_run: str | os.PathLike, out_dir: str | os.PathLike,
               *, progress: bool = True) -> dict:
    """DAgger from the training run folder ``base_run`` into ``out_dir`` (see the module doc).
    Returns what ``dagger.json`` holds."""
    from clonedrive.base.paths import check_output_folder
    from clonedrive.data.recipe import load_recipe
    from clonedrive.drivers.policy import load_policy
    from clonedrive.model.train import load_run_config

    base = Path(base_run)
    base_model = base / "model.keras"
    if not base_model.is_file() or not (base / "recipe.toml").is_file():
        raise FileNotFoundError(f"{base} is not a finished training run (model.keras and "
                                "recipe.toml expected: clonedrive train --out)")
    check_human_recordings(config.human)
    base_config = load_run_config(base)  # both read before anything is written
    base_recipe = load_recipe(base / "recipe.toml")
    out = check_output_folder(out_dir)
    settings = {**config_to_dict(config), "base": str(base.resolve())}
    check_rerun(out, settings)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "config.json", settings)

    _say(progress, "[dagger] expert reference laps")
    references = expert_references(config)
    rows = []
    _say(progress, "[dagger] iteration 0: the base model")
    rows.append({"iteration": 0, "method": "base", "beta": None, "labels": 0,
                 "labels_total": 0, "model": str(base_model),
                 "eval": evaluate_model(base_model, config, out / "iter_00" / "eval", references,
                                        progress=progress)})
    model = base_model
    folders: list[Path] = []
    labels_total = 0
    for iteration in range(1, config.iterations + 1):
        folder = out / f"iter_{iteration:02d}"
        beta = config.beta_at(iteration)
        _say(progress, f"[dagger] iteration {iteration}: collecting with beta {beta:.3f}")
        collected = _reuse_json(folder / "data" / "collect.json") or collect(
            load_policy(model), config, beta, folder / "data", seed=iteration, progress=progress)
        folders += [folder / "data" / item["folder"] for item in collected["tracks"]]
        labels_total += collected["labels"]
        _say(progress, f"[dagger] iteration {iteration}: {collected['labels']} labels, "
                       f"{collected['takeovers']} takeovers; retraining")
        model = retrain(base_config, aggregate_recipe(base_recipe, folders, config.human), model,
                        config.epochs, config.learning_rate, folder / "train",
                        seed=config.seed + iteration, progress=progress)
        rows.append({"iteration": iteration, "method": "dagger", "beta": round(beta, 4),
                     "labels": collected["labels"], "labels_total": labels_total,
                     "collect": {key: collected[key] for key in
                                 ("distance_km", "takeovers", "takeovers_per_km",
                                  "off_road_events", "off_road_per_km", "expert_share")},
                     "model": str(model),
                     "eval": evaluate_model(model, config, folder / "eval", references,
                                            progress=progress)})
        _write_report(out, config, rows, None, references)

    plain, plain_each = None, []
    if config.plain:
        # Earlier iterations' label counts first (with plain_each), then the last one's.
        counts = [(row["iteration"], row["labels_total"]) for row in rows[1:]]
        for iteration, labels in counts if config.plain_each else counts[-1:]:
            last = iteration == config.iterations
            folder = out / ("plain" if last else f"plain_{iteration:02d}")
            _say(progress, f"[dagger] plain cloning with {labels} extra expert labels "
                           f"({config.epochs * iteration} epochs)")
            entry = train_plain(config, base_config, base_recipe, base_model, labels, iteration,
                                folder, references, progress=progress)
            if last:
                plain = entry
            else:
                plain_each.append(entry)
                _write_report(out, config, rows, None, references, plain_each)
    return _write_report(out, config, rows, plain, references, plain_each)


def check_rerun(out: Path, settings: dict) -> None:
    """``ValueError`` naming each differing setting when ``out`` holds a DAgger run made with
    other ``settings`` (its config.json) than :data:`RERUN_MAY_CHANGE`: a rerun reuses every
    finished iteration, which must not then be labelled with settings it was not made with."""
    path = out / "config.json"
    if not path.is_file():
        return
    changed = changed_settings(read_json(path, what="config file"), settings,
                               may_change=RERUN_MAY_CHANGE)
    if changed:
        raise ValueError(f"{out} holds a DAgger run with other settings ({'; '.join(changed)}), "
                         "whose iterations would be reused as if made with the new ones; rerun "
                         "it with its own settings, or choose another --out")


def train_plain(config: DaggerConfig, base_config, base_recipe, base_model: Path, labels: int,
                iteration: int, folder: Path, references: dict, *, progress: bool) -> dict:
    """Plain cloning with ``labels`` extra expert labels, trained from the base model for as
    many epochs as DAgger had trained by ``iteration``, and evaluated as the iterations are."""
    recorded = _reuse_json(folder / "data" / "record.json")
    if recorded is None:
        recorded = record_plain(config, labels, folder / "data")
    else:  # reused only when recorded as this run asks (older folders hold no "asked")
        if recorded.get("noise") != config.plain_noise:
            raise ValueError(f"{folder / 'data'}: recorded with steering noise "
                             f"{recorded.get('noise')}, not the {config.plain_noise} asked for "
                             "(plain_noise); use another --out, or remove that folder")
        asked = recorded.get("asked", recorded.get("labels"))
        if asked != labels:
            raise ValueError(f"{folder / 'data'}: recorded for {asked} labels, not the "
                             f"{labels} DAgger collected by iteration {iteration}; use another "
                             "--out, or remove that folder")
    folders = [folder / "data" / item.name for item in sorted((folder / "data").iterdir())
               if (item / "driving_log.csv").is_file()]
    # The person's takeovers too: the comparison differs only in where the expert's labels are.
    model = retrain(base_config, aggregate_recipe(base_recipe, folders, config.human), base_model,
                    config.epochs * iteration, config.learning_rate, folder / "train",
                    seed=config.seed, progress=progress)
    return {"method": "plain", "iteration": iteration, "labels_total": recorded["labels"],
            "noise": recorded["noise"], "epochs": config.epochs * iteration, "model": str(model),
            "eval": evaluate_model(model, config, folder / "eval", references,
                                   progress=progress)}


def _reuse_json(path: Path) -> dict | None:
    """A finished stage's record (written atomically, so whole or absent), or None when the
    stage has not finished; a file that cannot be read is an error naming it, never taken
    for a stage to run again."""
    if not path.is_file():
        return None
    return read_json(path, what="DAgger stage record")


def _write_report(out: Path, config: DaggerConfig, rows: list[dict], plain: dict | None,
                  references: dict, plain_each: Sequence[dict] = ()) -> dict:
    report = {"config": dataclasses.asdict(config), "iterations": rows, "plain": plain,
              "plain_each": list(plain_each), "expert": references}
    write_json_atomic(out / DAGGER_JSON, report)
    plot_dagger(report, out / DAGGER_PNG)
    return report


def _say(enabled: bool, text: str) -> None:
    if enabled:
        print(text, flush=True)
