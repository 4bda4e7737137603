"""Train a steering network on recordings: recipe -> data set -> fit, checkpoint, resume.

The data set (samples, balancing, split, the decoded-image cache, ``dataset.json``'s report)
is made by :func:`clonedrive.data.dataset.build_dataset` from :meth:`TrainConfig.dataset_config`;
the per-epoch files and ``model.h5`` are written by :mod:`clonedrive.model.checkpoints`.
``train(config, source, out_dir)`` writes into ``out_dir``:

- ``model.keras``  the model of the epoch with the lowest validation loss;
- ``last.keras``   the model and optimiser state after the latest epoch (for ``resume``);
- ``model.h5``     a legacy HDF5 copy of ``model.keras`` for tools that expect one;
- ``history.csv``  per epoch: loss, val_loss (both include the L2 penalty, with a speed head
  the weighted speed loss, and with ``consistency`` its penalty), mse, val_mse (plain mean
  squared steering error), seconds; with a speed head also speed_mse, val_speed_mse (of the
  normalised target speed);
- ``loss.png``     training and validation loss per epoch;
- ``config.json``  the :class:`TrainConfig` (loadable with ``config.load_config``);
- ``recipe.toml``  the recipe used, with absolute paths (``resume`` reads it back);
- ``dataset.json`` sample counts, skipped rows and images by reason, the split used;
- ``steering_before.png`` / ``steering_after.png``  histograms around balancing;
- ``state.json``   epochs done and best validation loss, written last each epoch.

Every epoch-end file is written atomically (temp file + rename). A run killed mid-epoch is
resumed with ``resume=True`` from ``last.keras`` at the epoch after the last completed one;
shuffling and augmentation are drawn from ``(seed, epoch, batch)``, so the resumed epochs see
the batches the uninterrupted run would have seen.

Randomness: weight initialisers and dropout get explicit seeds from ``config.seed``, balancing,
splitting, shuffling and augmentation use ``numpy.random.Generator``s seeded from it; no global
random state is set.
"""

from __future__ import annotations

import json
import logging
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from clonedrive.base.config import (
    changed_settings,
    config_to_dict,
    load_config,
    save_config,
    write_json_atomic,
    write_text_atomic,
)
from clonedrive.data.dataset import Dataset, ImageHandoff, build_dataset, discard_cache
from clonedrive.data.recipe import (
    DEFAULT_CORRECTION,
    Recipe,
    default_recipe_for,
    load_recipe,
    recipe_to_toml,
)
from clonedrive.model.checkpoints import export_h5, run_recorder_class
from clonedrive.model.history import HISTORY_NAME, read_history
from clonedrive.model.train_config import TrainConfig
from clonedrive.network.crop import visible_rows

logger = logging.getLogger(__name__)

@dataclass(frozen=True)
class TrainResult:
    """What a training run produced."""

    out_dir: Path
    model_path: Path  # model.keras, the best epoch
    epochs_done: int  # total, including epochs before a resume
    best_epoch: int  # 1-based
    best_val_loss: float
    stopped_early: bool
    history: list[dict] = field(repr=False)
    dataset: dict = field(repr=False)  # what dataset.json holds


def resolve_source(source: Recipe | str | os.PathLike | Sequence[str | os.PathLike],
                   correction: float = DEFAULT_CORRECTION) -> Recipe:
    """A Recipe from a Recipe, a ``.toml`` recipe path, or recording folder(s)."""
    if isinstance(source, Recipe):
        return source
    if isinstance(source, str | os.PathLike):
        if Path(source).suffix.lower() == ".toml":
            return load_recipe(source)
        source = [source]
    return default_recipe_for(list(source), correction=correction)


def train(
    config: TrainConfig,
    source: Recipe | str | os.PathLike | Sequence[str | os.PathLike],
    out_dir: str | os.PathLike,
    *,
    resume: bool = False,
    progress: bool = True,
    notes: dict | None = None,
    handoff: ImageHandoff | None = None,
) -> TrainResult:
    """Train ``config.model`` on ``source`` (a Recipe, a recipe file, or recording folders)
    and write the run folder ``out_dir`` (see module doc).

    With ``resume``, continue the run in ``out_dir`` from ``last.keras``: ``config`` must
    match the saved ``config.json`` except for ``epochs``, ``early_stopping_patience`` and
    ``workers``. Without it, ``out_dir`` must not hold a previous run.

    ``notes``: what every model file written carries about how to drive it and the recipe
    that made it (:func:`clonedrive.network.driving_settings.notes_for`); a resumed run keeps
    its ``last.keras``'s notes when given none.

    ``handoff``: decoded images shared with the other stages of a multi-stage run; this run
    takes them if they are its data set's, and leaves its own there instead of deleting them.
    """
    out = Path(out_dir)
    recipe = resolve_source(source, config.correction)
    state = _prepare_run_folder(out, config, recipe, resume)
    if notes is None and resume and (out / "last.keras").is_file():
        from clonedrive.network.driving_settings import read_notes

        notes = read_notes(out / "last.keras") or None
    save_config(config, out / "config.json")
    write_text_atomic(out / "recipe.toml", recipe_to_toml(recipe))

    data: Dataset | None = None
    try:
        data = build_dataset(recipe, config.dataset_config(), out, progress=progress,
                             handoff=handoff)
        write_json_atomic(out / "dataset.json", data.report)
        _print(progress, data.summary)
        epochs_done = state["epochs_done"]
        history = read_history(out / HISTORY_NAME)[:epochs_done]
        model = _model(config, out, epochs_done, progress)
        train_batches, val_batches = _batches(config, data, model, epochs_done)
        recorder = run_recorder_class()(out, config, history, state, notes)
        if epochs_done < config.epochs and not recorder.should_stop():
            model.fit(
                train_batches,
                validation_data=val_batches,
                epochs=config.epochs,
                initial_epoch=epochs_done,
                shuffle=False,  # DrivingBatches shuffles, reproducibly
                verbose=_keras_verbosity(progress),
                callbacks=[recorder],
            )
    finally:
        if data is not None and handoff is not None:
            handoff.keep(data.cache)  # for the next stage; the handoff deletes it at the end
        else:
            if data is not None:
                data.close()
            discard_cache(out)  # interrupted while the data set was being made: its cache too

    if config.export_h5 and (out / "model.keras").is_file():
        export_h5(out / "model.keras", out / "model.h5", notes=notes)
    best = recorder.best_epoch()
    return TrainResult(
        out_dir=out,
        model_path=out / "model.keras",
        epochs_done=len(recorder.history),
        best_epoch=best[0],
        best_val_loss=best[1],
        stopped_early=recorder.stopped_early,
        history=list(recorder.history),
        dataset=data.report,
    )


def _model(config: TrainConfig, out: Path, epochs_done: int, progress: bool):
    """The compiled model to fit: ``last.keras`` after ``epochs_done`` completed epochs (a
    resume), else a new ``config.model`` (with ``init_from``'s weights when given)."""
    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()
    if epochs_done > 0:
        from clonedrive.model import consistency, losses
        from clonedrive.network.model_file import check_keras_file

        check_keras_file(out / "last.keras")  # bounded before Keras allocates
        model = keras.saving.load_model(
            out / "last.keras", safe_mode=True,
            custom_objects={**losses.CUSTOM_OBJECTS, **consistency.CUSTOM_OBJECTS})
        _print(progress, f"resuming after epoch {epochs_done} from {out / 'last.keras'}")
        return model
    from clonedrive.model.architectures import build_model

    model = build_model(config.model, seed=config.seed, dropout=config.dropout,
                        speed_head=config.speed_head, crop_top_px=config.crop_top_px)
    if config.init_from is not None:
        copied = load_initial_weights(model, config.init_from)
        _print(progress, f"initial weights of {copied} layer(s) from {config.init_from}")
    _compile(keras, model, config)
    return model


def _batches(config: TrainConfig, data: Dataset, model, epochs_done: int):
    """(training batches, shuffled and augmented as epoch ``epochs_done + 1`` draws them;
    validation batches)."""
    from clonedrive.data.augment import AugmentConfig
    from clonedrive.data.batches import DrivingBatches

    train_batches = DrivingBatches(
        data.train, data.cache, batch_size=config.batch_size, shuffle=True,
        augment=AugmentConfig(steering_per_px=config.shift_steering_per_px,
                              looks_probability=config.augment_looks,
                              saturation_min=config.looks_saturation)
        if config.augment else None, seed=config.seed,
        epoch=epochs_done, workers=config.workers, speed_head=config.speed_head,
        # Augment only the rows the network keeps after its crop (same pixels, less work).
        rows=visible_rows(model), partners=_partners(config, data.train),
    )
    val_batches = DrivingBatches(
        data.val, data.cache, batch_size=config.batch_size, workers=config.workers,
        speed_head=config.speed_head, partners=_partners(config, data.val),
    )
    return train_batches, val_batches


def _partners(config: TrainConfig, samples):
    """Each sample's next frame when training with ``consistency``, else None."""
    if not config.consistency:
        return None
    from clonedrive.data.neighbours import next_frames

    return next_frames(samples)


def _steering_loss(config: TrainConfig):
    if not config.consistency:
        return config.loss
    from clonedrive.model.consistency import ConsistentMSE

    return ConsistentMSE(config.consistency)


def _compile(keras, model, config: TrainConfig) -> None:
    optimizer = keras.optimizers.Adam(learning_rate=config.learning_rate)
    if not config.speed_head:
        model.compile(optimizer=optimizer, loss=_steering_loss(config),
                      metrics=[keras.metrics.MeanSquaredError(name="mse")])
        return
    from clonedrive.model.losses import speed_loss
    from clonedrive.network.contract import SPEED_OUTPUT, STEERING_OUTPUT

    model.compile(
        optimizer=optimizer,
        loss={STEERING_OUTPUT: _steering_loss(config), SPEED_OUTPUT: speed_loss(config.speed_loss)},
        loss_weights={STEERING_OUTPUT: 1.0, SPEED_OUTPUT: config.speed_loss_weight},
        metrics={STEERING_OUTPUT: [keras.metrics.MeanSquaredError(name="mse")],
                 SPEED_OUTPUT: [keras.metrics.MeanSquaredError(name="mse")]},
    )


def load_initial_weights(model, path: str | os.PathLike) -> int:
    """Copy into ``model`` the weights of every layer of the model at ``path`` that has the same
    name and weight shapes (a model without a speed head can start one with it). Returns the
    number of layers copied; ``ValueError`` if none match or the file does not load."""
    from clonedrive.network.model_file import load_model

    source = load_model(path)
    by_name = {layer.name: layer for layer in source.layers}
    copied = 0
    for layer in model.layers:
        weights = layer.get_weights()
        other = by_name.get(layer.name)
        if not weights or other is None:
            continue
        theirs = other.get_weights()
        if [w.shape for w in theirs] == [w.shape for w in weights]:
            layer.set_weights(theirs)
            copied += 1
    if copied == 0:
        raise ValueError(f"{path}: no layer matches the {model.name} model by name and shape")
    return copied


def load_run_config(out_dir: str | os.PathLike) -> TrainConfig:
    """The TrainConfig a run folder was trained with."""
    return load_config(TrainConfig, Path(out_dir) / "config.json")


# --- run folder -------------------------------------------------------------------------------

_RESUME_MAY_CHANGE = ("epochs", "early_stopping_patience", "workers", "init_from")


def _prepare_run_folder(out: Path, config: TrainConfig, recipe: Recipe, resume: bool) -> dict:
    state_path = out / "state.json"
    if resume:
        if not state_path.is_file() or not (out / "last.keras").is_file():
            if state_path.is_file() or (out / "config.json").is_file():
                logger.warning("%s: no completed epoch to resume from; starting over", out)
            return {"epochs_done": 0, "best_val_loss": None, "best_epoch": None}
        changed = changed_settings(config_to_dict(load_run_config(out)), config_to_dict(config),
                                   may_change=_RESUME_MAY_CHANGE)
        if changed:
            raise ValueError(f"{out}: cannot resume with different settings: "
                             + ", ".join(changed))
        saved_recipe = load_recipe(out / "recipe.toml")
        if saved_recipe.recordings != recipe.recordings:
            raise ValueError(
                f"{out}: cannot resume with a different recipe than {out / 'recipe.toml'}"
            )
        with open(state_path, encoding="utf-8") as handle:
            return json.load(handle)
    if state_path.exists() or (out / "model.keras").exists():
        raise FileExistsError(
            f"{out} already holds a training run; resume it (--resume) or choose another --out"
        )
    out.mkdir(parents=True, exist_ok=True)
    return {"epochs_done": 0, "best_val_loss": None, "best_epoch": None}


def _print(enabled: bool, text: str) -> None:
    if enabled:
        print(text, flush=True)


def _keras_verbosity(progress: bool) -> int:
    """Keras's ``verbose``: nothing without progress; a live bar on a terminal; otherwise one
    line per epoch, so a log file holds the epochs rather than the bar's frames."""
    if not progress:
        return 0
    return 1 if sys.stdout.isatty() else 2
