"""Train a steering network on recordings: recipe -> samples -> balance -> split -> fit.

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
import math
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from clonedrive.config import (
    atomic_path,
    changed_settings,
    config_to_dict,
    load_config,
    save_config,
    write_json_atomic,
    write_text_atomic,
)
from clonedrive.data.recipe import (
    CORRECTION_RANGE,
    DEFAULT_CORRECTION,
    Recipe,
    default_recipe_for,
    load_recipe,
    recipe_to_toml,
)
from clonedrive.interrupts import raise_if_lost
from clonedrive.model.history import HISTORY_NAME, read_history, write_history
from clonedrive.network.crop import visible_rows

logger = logging.getLogger(__name__)

CACHE_MODES = ("auto", "memory", "memmap")
#: With a speed head, balancing keeps every sample whose speed label is below this [mph]
#: (the expert slowing for a bend), whatever its steering.
SLOWING_LABEL_MPH = 28.5
CACHE_FILE = "image_cache.u8"


#: The largest learning rate training accepts: above it Adam only diverges.
MAX_LEARNING_RATE = 1.0
#: The largest count each setting takes, from the command line or a recipe file alike: a
#: batch, a worker pool or a history is sized from them before training starts.
MAX_COUNTS = {"epochs": 10_000, "batch_size": 65_536, "early_stopping_patience": 10_000,
              "workers": 1_024, "balance_bins": 10_000}


@dataclass(frozen=True)
class TrainConfig:
    """Training settings; defaults are the write-up's."""

    model: str = "seed"  # seed | pilotnet | fast (see model.architectures)
    learning_rate: float = 1e-4  # Adam
    loss: str = "mse"
    batch_size: int = 256
    epochs: int = 7  # total epochs, counting any done before a resume
    correction: float = DEFAULT_CORRECTION  # side-camera correction of a DIR-only recipe
    balance: bool = True  # the write-up's steering histogram balancing
    balance_bins: int = 20
    split: str = "random"  # random | blocks | recording (see data.split)
    val_fraction: float = 0.2
    block_s: float = 10.0  # block length of the "blocks" split, seconds
    augment: bool = True  # training-only augmentation (see data.augment)
    seed: int = 0
    early_stopping_patience: int | None = None  # stop after this many epochs without a best
    dropout: float = 0.0  # 0 = off
    workers: int = 1  # PyDataset worker threads
    cache: str = "auto"  # decoded images: memory | memmap (a file in out_dir) | auto
    cache_memory_limit_mb: int = 2048  # "auto" uses a memmap above this size
    export_h5: bool = True  # also write model.h5
    speed_head: bool = False  # also learn the expert's target speed (output "target_speed")
    speed_loss_weight: float = 1.0  # weight of the speed MSE beside the steering MSE
    speed_loss: str = "mse"  # or "censored": labels at the top speed are lower bounds
    speed_headroom: float = 1.0  # labels at the top speed rise up to this multiple of it
    init_from: str | None = None  # start from this model's weights (layers matched by name)
    crop_top_px: int = 80  # rows the model cuts from the top (model.architectures.CROP_TOP_PX)
    consistency: float = 0.0  # weight of the next-frame consistency penalty (model.consistency)

    def __post_init__(self) -> None:
        from clonedrive.data.split import SPLIT_KINDS

        if self.split not in SPLIT_KINDS:
            raise ValueError(f"split {self.split!r}; expected one of: {', '.join(SPLIT_KINDS)}")
        if self.cache not in CACHE_MODES:
            raise ValueError(f"cache {self.cache!r}; expected one of: {', '.join(CACHE_MODES)}")
        if self.batch_size < 1 or self.epochs < 1:
            raise ValueError("batch_size and epochs must be >= 1")
        low, high = CORRECTION_RANGE
        if not (math.isfinite(self.correction) and low <= self.correction <= high):
            raise ValueError(f"correction must be in [{low:g}, {high:g}], got {self.correction}")
        if not (math.isfinite(self.block_s) and self.block_s > 0):
            raise ValueError(f"block_s must be a positive number of seconds, got {self.block_s}")
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in (0, 1), got {self.val_fraction}")
        if not 0 < self.learning_rate <= MAX_LEARNING_RATE:  # also NaN and infinity
            raise ValueError(f"learning_rate must be in (0, {MAX_LEARNING_RATE:g}], got "
                             f"{self.learning_rate}")
        if not 0.0 <= self.dropout < 1.0:  # also NaN
            raise ValueError(f"dropout must be in [0, 1), got {self.dropout}")
        if self.early_stopping_patience is not None and self.early_stopping_patience < 1:
            raise ValueError("early_stopping_patience must be >= 1 or None")
        for name, most in MAX_COUNTS.items():
            value = getattr(self, name)
            if value is not None and value > most:
                raise ValueError(f"{name} must be at most {most:,}, got {value:,}")
        if not (self.speed_loss_weight >= 0 and math.isfinite(self.speed_loss_weight)):
            raise ValueError(f"speed_loss_weight must be >= 0, got {self.speed_loss_weight}")
        from clonedrive.model.losses import SPEED_LOSSES

        if self.speed_loss not in SPEED_LOSSES:
            raise ValueError(f"speed_loss {self.speed_loss!r}; expected one of: "
                             f"{', '.join(SPEED_LOSSES)}")
        if not (math.isfinite(self.speed_headroom) and 1.0 <= self.speed_headroom <= 2.0):
            raise ValueError(f"speed_headroom must be in [1, 2], got {self.speed_headroom}")
        if not (math.isfinite(self.consistency) and self.consistency >= 0):
            raise ValueError(f"consistency must be >= 0, got {self.consistency}")
        if self.consistency and self.loss != "mse":
            raise ValueError(f"consistency adds to the mse loss, not to {self.loss!r}")


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
) -> TrainResult:
    """Train ``config.model`` on ``source`` (a Recipe, a recipe file, or recording folders)
    and write the run folder ``out_dir`` (see module doc).

    With ``resume``, continue the run in ``out_dir`` from ``last.keras``: ``config`` must
    match the saved ``config.json`` except for ``epochs``, ``early_stopping_patience`` and
    ``workers``. Without it, ``out_dir`` must not hold a previous run.

    ``notes``: what every model file written carries about how to drive it and the recipe
    that made it (:func:`clonedrive.network.driving_settings.notes_for`); a resumed run keeps
    its ``last.keras``'s notes when given none.
    """
    from clonedrive.keras_backend import import_keras

    keras = import_keras()

    from clonedrive.data.augment import AugmentConfig
    from clonedrive.data.batches import DrivingBatches
    from clonedrive.model.architectures import build_model

    out = Path(out_dir)
    recipe = resolve_source(source, config.correction)
    state = _prepare_run_folder(out, config, recipe, resume)
    if notes is None and resume and (out / "last.keras").is_file():
        from clonedrive.network.driving_settings import read_notes

        notes = read_notes(out / "last.keras") or None
    save_config(config, out / "config.json")
    write_text_atomic(out / "recipe.toml", recipe_to_toml(recipe))

    data = None
    try:
        data = _prepare_data(config, recipe, out, progress=progress)
        write_json_atomic(out / "dataset.json", data.report)
        _print(progress, data.summary)
        epochs_done = state["epochs_done"]
        history = read_history(out / HISTORY_NAME)[:epochs_done]
        if epochs_done > 0:
            from clonedrive.model import consistency, losses
            from clonedrive.network.model_file import check_keras_file

            check_keras_file(out / "last.keras")  # bounded before Keras allocates
            model = keras.saving.load_model(
                out / "last.keras", safe_mode=True,
                custom_objects={**losses.CUSTOM_OBJECTS, **consistency.CUSTOM_OBJECTS})
            _print(progress, f"resuming after epoch {epochs_done} from {out / 'last.keras'}")
        else:
            model = build_model(config.model, seed=config.seed, dropout=config.dropout,
                                speed_head=config.speed_head, crop_top_px=config.crop_top_px)
            if config.init_from is not None:
                copied = load_initial_weights(model, config.init_from)
                _print(progress, f"initial weights of {copied} layer(s) from {config.init_from}")
            _compile(keras, model, config)
        train_batches = DrivingBatches(
            data.train, data.cache, batch_size=config.batch_size, shuffle=True,
            augment=AugmentConfig() if config.augment else None, seed=config.seed,
            epoch=epochs_done, workers=config.workers, speed_head=config.speed_head,
            # Augment only the rows the network keeps after its crop (same pixels, less work).
            rows=visible_rows(model), partners=_partners(config, data.train),
        )
        val_batches = DrivingBatches(
            data.val, data.cache, batch_size=config.batch_size, workers=config.workers,
            speed_head=config.speed_head, partners=_partners(config, data.val),
        )
        recorder = _run_recorder_class()(out, config, history, state, notes)
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
        if data is not None:
            data.cache.close(delete=True)
        # Interrupted while the cache was being made: its file goes too.
        (out / CACHE_FILE).unlink(missing_ok=True)

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


def export_h5(keras_path: str | os.PathLike, h5_path: str | os.PathLike, *,
              notes: dict | None = None) -> Path:
    """Save the model at ``keras_path`` in the legacy HDF5 format (atomically), with ``notes``
    (network.driving_settings) when given. A model with a speed head is saved with its
    steering output only: Udacity's drive.py expects one output."""
    from clonedrive.keras_backend import import_keras

    keras = import_keras()

    h5_path = Path(h5_path)
    model = keras.saving.load_model(keras_path, safe_mode=True, compile=False)
    if len(model.outputs) > 1:
        model = keras.Model(model.inputs, model.outputs[0], name=model.name)
    logging.getLogger("absl").setLevel(logging.ERROR)  # "HDF5 is legacy": we know
    with atomic_path(h5_path) as temporary:
        model.save(temporary)
        if notes:
            from clonedrive.network.driving_settings import write_notes

            write_notes(temporary, notes)
    return h5_path


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


# --- data ---------------------------------------------------------------------------------


@dataclass
class _PreparedData:
    train: object  # Samples
    val: object  # Samples
    cache: object  # ImageCache
    report: dict
    summary: str


def _prepare_data(config: TrainConfig, recipe: Recipe, out: Path, *, progress: bool
                  ) -> _PreparedData:
    """expand -> speed-label headroom -> balance -> split -> decode the used images once
    (unusable ones skipped)."""
    from clonedrive.data.balance import save_balance_plots
    from clonedrive.data.recipe import expand
    from clonedrive.data.split import split_samples

    samples = expand(recipe)
    if len(samples) == 0:
        raise ValueError(
            f"no usable samples in {', '.join(str(spec.path) for spec in recipe.recordings)}"
            + (f" (skipped rows: {samples.skipped})" if samples.skipped else "")
        )
    lines = [
        f"{len(recipe.recordings)} recording(s), {samples.rows_read} usable rows, "
        f"{len(samples)} samples"
    ]
    if samples.skipped:
        lines.append(f"skipped rows: {_counts_text(samples.skipped)}")
    if samples.side_images_missing:
        lines.append(f"{samples.side_images_missing} rows lack a side image: they train with "
                     "the cameras they have")
    if config.speed_head:
        lines.append(
            f"speed labels: the expert's target speed on {samples.rows_with_target_speed} rows, "
            f"the recorded speed on {samples.rows_read - samples.rows_with_target_speed}")

    # Headroom first: the profile is counted back along whole recordings, before balancing
    # drops any of their samples.
    raised = 0
    if config.speed_head and config.speed_headroom != 1.0:
        from clonedrive.data.speed_labels import with_headroom

        labels, raised = with_headroom(samples.target_speed_mph, samples.recording, samples.row,
                                       samples.time_s, samples.recorded_speed_mph,
                                       config.speed_headroom)
        samples = replace(samples, target_speed_mph=labels)
        lines.append(f"speed head: {raised} labels at the top speed continue the expert's "
                     f"braking profile up to {config.speed_headroom:g}x it (headroom, before "
                     "balancing)")

    samples, balanced, kept_for_speed = _balance(config, samples, lines)
    save_balance_plots(balanced, out / "steering_before.png", out / "steering_after.png")
    split = split_samples(
        samples, config.split, np.random.default_rng([config.seed, 2]),
        val_fraction=config.val_fraction, block_s=config.block_s,
    )
    lines.append(split.description)

    samples = samples.compact()
    cache = _open_cache(config, samples, out)
    lines.append(
        f"image cache: {len(cache)} images, rows {cache.rows[0]}-{cache.rows[1] - 1} of each, "
        f"{cache.nbytes / 1e6:.0f} MB "
        + (f"memmap {cache.memmap_path}" if cache.memmap_path else "in memory")
    )
    try:
        failed = cache.fill(workers=2, progress=progress)
    except BaseException:  # interrupted (Ctrl-C, SIGTERM) or failed: no cache left behind
        cache.close(delete=True)
        raise
    bad_images: dict[str, int] = {}
    for error in failed.values():
        bad_images[error.reason] = bad_images.get(error.reason, 0) + 1
    train_samples, dropped_train = samples.subset(split.train).drop_images(failed)
    val_samples, dropped_val = samples.subset(split.val).drop_images(failed)
    if failed:
        lines.append(
            f"skipped images: {_counts_text(bad_images)} ({dropped_train + dropped_val} samples)"
        )
        for error in list(failed.values())[:5]:
            logger.warning("skipped image: %s", error)
    if len(train_samples) == 0 or len(val_samples) == 0:
        cache.close(delete=True)
        raise ValueError(
            f"after skipping unusable images, {len(train_samples)} training and "
            f"{len(val_samples)} validation samples remain; need at least one of each"
        )

    report = {
        "recordings": [
            {"name": spec.name, "path": str(spec.path), "cameras": spec.cameras,
             "correction": spec.correction, "steering_offset": spec.steering_offset,
             "flip": spec.flip, "weight": spec.weight}
            for spec in recipe.recordings
        ],
        "rows_read": samples.rows_read,
        "side_images_missing": samples.side_images_missing,
        "rows_with_target_speed": samples.rows_with_target_speed,
        "skipped_rows": samples.skipped,
        "skipped_row_details": samples.skipped_details[:100],
        "samples_before_balance": int(balanced.counts_before.sum()),
        "samples_after_balance": int(balanced.counts_after.sum()) + kept_for_speed,
        "speed_samples_kept": kept_for_speed,
        "speed_labels_raised": raised,  # labels at the top speed trained with headroom
        "balance": {
            "enabled": config.balance,
            "bin_edges": [round(float(edge), 6) for edge in balanced.bin_edges],
            "counts_before": balanced.counts_before.tolist(),
            "counts_after": balanced.counts_after.tolist(),
            "target_per_bin": balanced.target,
        },
        "split": {"kind": split.kind, "description": split.description,
                  "val_fraction": config.val_fraction,
                  "block_s": config.block_s if split.kind == "blocks" else None},
        "skipped_images": bad_images,
        "skipped_image_samples": dropped_train + dropped_val,
        "train_samples": len(train_samples),
        "val_samples": len(val_samples),
        "images_cached": len(cache),
    }
    lines.append(f"training on {len(train_samples)} samples, validating on {len(val_samples)}")
    return _PreparedData(train_samples, val_samples, cache, report, "\n".join(lines))


def _balance(config: TrainConfig, samples, lines: list[str]):
    """(the samples kept, the balancing result for the histograms, samples kept back for the
    speed head), the steps said in ``lines``."""
    from clonedrive.data.balance import balance_steering

    balanced = balance_steering(samples.steering, np.random.default_rng([config.seed, 1]),
                                bins=config.balance_bins)
    if not config.balance:
        lines.append(f"balancing off: {len(samples)} samples")
        return samples, _unbalanced(balanced), 0
    keep, kept_for_speed = balanced.keep, 0
    if config.speed_head:
        # Steering balancing thins out the straight-ahead samples, and with them the braking
        # zones before bends: the samples the speed head learns slowing from.
        slowing = np.flatnonzero(samples.target_speed_mph < SLOWING_LABEL_MPH)
        keep = np.union1d(keep, slowing)
        kept_for_speed = len(keep) - len(balanced.keep)
        lines.append(f"speed head: {kept_for_speed} samples where the "
                     f"expert slows below {SLOWING_LABEL_MPH:g} mph kept back")
    lines.append(balanced.summary())
    return samples.subset(keep), balanced, kept_for_speed


def _open_cache(config: TrainConfig, samples, out: Path):
    """The decoded-image cache ``config.cache`` asks for (memory, a memmap in ``out``, or
    memory up to the limit and a memmap above it), holding only the rows the network and its
    augmentation read (:func:`cached_rows`)."""
    from clonedrive.data.batches import ImageCache

    rows = cached_rows(config)
    if config.cache == "memory":
        return ImageCache(samples.unique_paths, rows=rows)
    if config.cache == "memmap":
        return ImageCache(samples.unique_paths, memmap_path=out / CACHE_FILE,
                          memory_limit_bytes=0, rows=rows)
    return ImageCache(samples.unique_paths, memmap_path=out / CACHE_FILE,
                      memory_limit_bytes=config.cache_memory_limit_mb * 1024**2, rows=rows)


def cached_rows(config: TrainConfig) -> tuple[int, int]:
    """The frame rows training reads: the network's crop, widened by augmentation's largest
    vertical shift (a shifted picture's visible rows come from up to that far away)."""
    from clonedrive.data.augment import AugmentConfig
    from clonedrive.model.architectures import CROP_BOTTOM_PX
    from clonedrive.udacity_spec import IMAGE_HEIGHT

    margin = AugmentConfig().vertical_shift_max_px if config.augment else 0
    return (max(0, config.crop_top_px - margin),
            min(IMAGE_HEIGHT, IMAGE_HEIGHT - CROP_BOTTOM_PX + margin))


def _unbalanced(result):
    """A BalanceResult that keeps everything (balancing off), for the histograms."""
    import dataclasses

    return dataclasses.replace(
        result,
        keep=np.arange(int(result.counts_before.sum())),
        counts_after=result.counts_before.copy(),
        keep_probability=np.ones_like(result.keep_probability),
    )


def _counts_text(counts: dict[str, int]) -> str:
    return ", ".join(f"{count} {reason}" for reason, count in counts.items())


# --- per-epoch bookkeeping ------------------------------------------------------------------


def _run_recorder_class():
    """The Keras callback class that records a run (built on first use: keras is heavy)."""
    from clonedrive.keras_backend import import_keras

    keras = import_keras()

    class RunRecorder(keras.callbacks.Callback):
        """After every epoch: last.keras, model.keras if best, history.csv, loss.png, state.json
        (in that order, each atomically); early stopping from the whole history."""

        def __init__(self, out: Path, config: TrainConfig, history: list[dict], state: dict,
                     notes: dict | None = None):
            super().__init__()
            self.out = out
            self.notes = notes
            self.config = config
            self.history = list(history)
            self.state = dict(state)
            self.stopped_early = False
            self._epoch_started = time.perf_counter()

        def best_epoch(self) -> tuple[int, float]:
            if not self.history:
                return 0, math.nan
            best = min(self.history, key=lambda row: row["val_loss"])
            return int(best["epoch"]), float(best["val_loss"])

        def should_stop(self) -> bool:
            patience = self.config.early_stopping_patience
            if patience is None or not self.history:
                return False
            return len(self.history) - self.best_epoch()[0] >= patience

        def on_epoch_begin(self, epoch, logs=None):
            self._epoch_started = time.perf_counter()

        def on_train_batch_end(self, batch, logs=None):
            raise_if_lost()  # a SIGTERM whose exception a destructor swallowed ends here

        def on_test_batch_end(self, batch, logs=None):
            raise_if_lost()

        def on_epoch_end(self, epoch, logs=None):
            logs = logs or {}
            row = {
                "epoch": epoch + 1,
                "loss": float(logs.get("loss", math.nan)),
                "val_loss": float(logs.get("val_loss", math.nan)),
                "mse": float(logs.get("mse", logs.get("steering_mse", math.nan))),
                "val_mse": float(logs.get("val_mse", logs.get("val_steering_mse", math.nan))),
                "seconds": round(time.perf_counter() - self._epoch_started, 3),
            }
            if self.config.speed_head:
                row["speed_mse"] = float(logs.get("target_speed_mse", math.nan))
                row["val_speed_mse"] = float(logs.get("val_target_speed_mse", math.nan))
            previous_best = self.best_epoch()[1] if self.history else math.inf
            self.history.append(row)
            _save_model_atomic(self.model, self.out / "last.keras", self.notes)
            if not row["val_loss"] >= previous_best:  # first epoch, a new best, or NaN history
                _save_model_atomic(self.model, self.out / "model.keras", self.notes)
            write_history(self.out / HISTORY_NAME, self.history)
            plot_loss(self.history, self.out / "loss.png",
                      consistency=bool(self.config.consistency))
            best_epoch, best_loss = self.best_epoch()
            self.state = {"epochs_done": epoch + 1, "best_epoch": best_epoch,
                          "best_val_loss": best_loss}
            write_json_atomic(self.out / "state.json", self.state)
            if self.should_stop():
                self.stopped_early = True
                self.model.stop_training = True
                print(
                    f"early stopping: no better validation loss for "
                    f"{self.config.early_stopping_patience} epoch(s); best epoch {best_epoch}",
                    flush=True,
                )

    return RunRecorder

def _save_model_atomic(model, path: Path, notes: dict | None = None) -> None:
    with atomic_path(path) as temporary:
        model.save(temporary)
        if notes:
            from clonedrive.network.driving_settings import write_notes

            write_notes(temporary, notes)


def plot_loss(history: list[dict], path: str | os.PathLike, *, consistency: bool = False
              ) -> Path:
    """Training and validation loss per epoch as a PNG (matplotlib Agg), atomically; the axis
    names what the loss holds (``consistency``: the run trained with that penalty)."""
    import textwrap

    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    path = Path(path)
    epochs = [row["epoch"] for row in history]
    figure = Figure(figsize=(7, 4), dpi=100)
    axes = figure.add_subplot()
    axes.plot(epochs, [row["loss"] for row in history], "o-", label="training loss")
    axes.plot(epochs, [row["val_loss"] for row in history], "s-", label="validation loss")
    axes.set_xlabel("epoch")
    speed = bool(history) and "speed_mse" in history[0]
    terms = ["steering MSE"] + (["consistency"] if consistency else []) + (
        ["speed MSE", "L2"] if speed else ["any L2 penalty"])
    axes.set_ylabel(textwrap.fill(f"loss ({' + '.join(terms)})", 40))  # fits the axis
    axes.set_title("training and validation loss")
    axes.xaxis.set_major_locator(MaxNLocator(integer=True))
    axes.grid(True, alpha=0.3)
    axes.legend()
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png")
    return path


def _keras_verbosity(progress: bool) -> int:
    """Keras's ``verbose``: nothing without progress; a live bar on a terminal; otherwise one
    line per epoch, so a log file holds the epochs rather than the bar's frames."""
    if not progress:
        return 0
    return 1 if sys.stdout.isatty() else 2
