"""What a training run writes as it goes: per epoch ``last.keras`` (with its training state,
for resuming), ``model.keras`` (a new best, the network alone: see :func:`portable_copy`),
``history.csv``, ``loss.png`` and ``state.json``, each atomically and in that order, and
at its end the legacy ``model.h5``.

:func:`run_recorder_class` gives the Keras callback that writes the per-epoch files and decides
early stopping from the whole history (one of its own, so that a resumed run stops where the
uninterrupted one would have); ``state.json`` is written last, so a run killed mid-epoch is
resumed (``model.train``) from the last epoch whose files are all whole.
"""

from __future__ import annotations

import logging
import math
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

from clonedrive.base.config import atomic_path, write_json_atomic
from clonedrive.base.interrupts import raise_if_lost
from clonedrive.model.history import HISTORY_NAME, write_history

if TYPE_CHECKING:
    from clonedrive.model.train_config import TrainConfig


def run_recorder_class():
    """The Keras callback class that records a run (built on first use: keras is heavy)."""
    from clonedrive.base.keras_backend import import_keras

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
            save_model_atomic(self.model, self.out / "last.keras", self.notes)
            if not row["val_loss"] >= previous_best:  # first epoch, a new best, or NaN history
                save_model_atomic(portable_copy(self.model), self.out / "model.keras",
                                  self.notes)
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


def portable_copy(model):
    """``model`` without its training state (loss, optimizer, metrics): the network and its
    weights, which plain Keras loads with ``safe_mode=True`` and no clonedrive class. A model
    saved compiled with a fine-tune's ``ConsistentMSE`` loss does not load outside clonedrive;
    ``last.keras`` keeps that state, for resuming."""
    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()
    copy = keras.Model.from_config(model.get_config())  # the config holds no compile state
    copy.set_weights(model.get_weights())
    return copy


def save_model_atomic(model, path: Path, notes: dict | None = None) -> None:
    with atomic_path(path) as temporary:
        model.save(temporary)
        if notes:
            from clonedrive.network.driving_settings import write_notes

            write_notes(temporary, notes)


def plot_loss(history: list[dict], path: str | os.PathLike, *, consistency: bool = False,
              second_stage_from: int | None = None) -> Path:
    """Training and validation loss per epoch as a PNG (matplotlib Agg), atomically; the axis
    names what the loss holds (``consistency``: the run trained with that penalty).
    ``second_stage_from``: the epoch where a second training stage (a fine-tune) starts, marked
    by a dashed line."""
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
    penalty = "consistency" if second_stage_from is None else "the fine-tune's consistency"
    terms = ["steering MSE"] + ([penalty] if consistency else []) + (
        ["speed MSE", "L2"] if speed else ["any L2 penalty"])
    axes.set_ylabel(textwrap.fill(f"loss ({' + '.join(terms)})", 40))  # fits the axis
    axes.set_title("training and validation loss")
    if second_stage_from is not None:
        axes.axvline(second_stage_from - 0.5, color="grey", linestyle="--", linewidth=1)
        axes.annotate("fine-tune", (second_stage_from - 0.5, 1.0),
                      xycoords=("data", "axes fraction"), xytext=(4, -14),
                      textcoords="offset points", color="grey")
    axes.xaxis.set_major_locator(MaxNLocator(integer=True))
    axes.grid(True, alpha=0.3)
    axes.legend()
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png")
    return path


def export_h5(keras_path: str | os.PathLike, h5_path: str | os.PathLike, *,
              notes: dict | None = None) -> Path:
    """Save the model at ``keras_path`` in the legacy HDF5 format (atomically), with ``notes``
    (drivers.driving_settings) when given. A model with a speed head is saved with its
    steering output only: Udacity's drive.py expects one output."""
    from clonedrive.base.keras_backend import import_keras

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
