"""End-to-end training on real Udacity recordings: every output file, resume, skipped images."""

from __future__ import annotations

import csv
import dataclasses
import json
import shutil
from pathlib import Path

import keras
import numpy as np
import pytest

from clonedrive.base.config import load_config
from clonedrive.cli import main
from clonedrive.data.driving_log import read_driving_log
from clonedrive.model.checkpoints import run_recorder_class
from clonedrive.model.train import train
from clonedrive.model.train_config import TrainConfig
from clonedrive.recipes.book import load_recipe_file

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"
OUTPUTS = {
    "model.keras", "last.keras", "model.h5", "history.csv", "loss.png", "config.json",
    "recipe.toml", "dataset.json", "steering_before.png", "steering_after.png", "state.json",
}
FAST = TrainConfig(model="fast", batch_size=64, epochs=2, learning_rate=1e-3)


@pytest.fixture(scope="module")
def damaged_recordings(tmp_path_factory) -> list[Path]:
    """Copies of two real recordings; the lake one with a truncated JPEG and a missing one."""
    root = tmp_path_factory.mktemp("recordings")
    folders = []
    for name in ("lake_posix_mixed_columns", "mountain_windows_paths"):
        shutil.copytree(FIXTURES / name, root / name)
        folders.append(root / name)
    rows = read_driving_log(folders[0]).rows
    rows[5].center.unlink()  # the reader skips this row (image_missing)
    data = rows[9].left.read_bytes()
    rows[9].left.write_bytes(data[: len(data) // 3])  # exists, but only a third of a JPEG
    return folders


def _weights(path: Path) -> list[np.ndarray]:
    return keras.saving.load_model(path, safe_mode=True).get_weights()


@pytest.mark.slow
def test_train_writes_every_output_and_resumes(damaged_recordings, tmp_path: Path) -> None:
    interrupted = tmp_path / "interrupted"
    first = train(dataclasses.replace(FAST, epochs=1), damaged_recordings, interrupted,
                  progress=False)
    assert first.epochs_done == 1
    assert OUTPUTS <= {path.name for path in interrupted.iterdir()}
    assert not list(interrupted.glob("image_cache*"))  # the decoded-image cache is removed

    resumed = train(FAST, damaged_recordings, interrupted, resume=True, progress=False)
    straight = train(FAST, damaged_recordings, tmp_path / "straight", progress=False)

    assert resumed.epochs_done == straight.epochs_done == 2
    with open(interrupted / "history.csv", encoding="utf-8") as handle:
        history = list(csv.DictReader(handle))
    assert [int(row["epoch"]) for row in history] == [1, 2]
    assert float(history[0]["val_loss"]) == pytest.approx(first.history[0]["val_loss"])
    # The resumed run saw the batches the uninterrupted one saw: same weights.
    for resumed_weight, straight_weight in zip(
        _weights(interrupted / "last.keras"), _weights(tmp_path / "straight" / "last.keras"),
        strict=True,
    ):
        np.testing.assert_allclose(resumed_weight, straight_weight, rtol=1e-5, atol=1e-6)

    # The best model by validation loss, loadable in safe mode, also as .h5.
    best = keras.saving.load_model(interrupted / "model.keras", safe_mode=True)
    assert resumed.best_val_loss == min(row["val_loss"] for row in resumed.history)
    frames = np.zeros((2, 160, 320, 3), dtype=np.uint8)
    expected = np.asarray(best.predict(frames, verbose=0))
    h5 = keras.saving.load_model(interrupted / "model.h5", safe_mode=True, compile=False)
    np.testing.assert_allclose(np.asarray(h5.predict(frames, verbose=0)), expected, atol=1e-6)
    assert expected.shape == (2, 1)

    config = load_config(TrainConfig, interrupted / "config.json")
    assert config == FAST and config.split == "random"
    dataset = json.loads((interrupted / "dataset.json").read_text(encoding="utf-8"))
    assert dataset["skipped_rows"] == {"image_missing": 1}
    assert dataset["skipped_images"] == {"image_corrupt": 1}
    assert dataset["skipped_image_samples"] >= 1
    assert dataset["split"]["kind"] == "random"
    assert dataset["samples_before_balance"] == (139 * 3) * 2
    assert dataset["train_samples"] + dataset["val_samples"] == (
        dataset["samples_after_balance"] - dataset["skipped_image_samples"]
    )
    assert sum(dataset["balance"]["counts_after"]) == dataset["samples_after_balance"]


def test_train_refuses_to_overwrite_or_resume_with_other_settings(
    damaged_recordings, tmp_path: Path
) -> None:
    out = tmp_path / "run"
    out.mkdir()
    (out / "state.json").write_text('{"epochs_done": 1}', encoding="utf-8")
    with pytest.raises(FileExistsError, match="already holds a training run"):
        train(FAST, damaged_recordings, out, progress=False)
    (out / "last.keras").write_bytes(b"")
    (out / "config.json").write_text(json.dumps(dataclasses.asdict(FAST)), encoding="utf-8")
    with pytest.raises(ValueError, match=r"cannot resume with different settings: model 'fast'"):
        train(dataclasses.replace(FAST, model="seed"), damaged_recordings, out, resume=True,
              progress=False)


def test_cli_train_folders_with_block_split(damaged_recordings, tmp_path: Path, capsys) -> None:
    out = tmp_path / "cli"
    code = main([
        "train", *map(str, damaged_recordings), "--model", "fast", "--epochs", "1",
        "--batch-size", "128", "--split", "blocks", "--no-h5", "--out", str(out), "--json",
    ])
    assert code == 0
    # --epochs sets the default recipe's first stage; its fine-tune keeps its own epochs.
    finetune_epochs = load_recipe_file("best").finetune[-1]["epochs"]
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["epochs_done"] == finetune_epochs and summary["split"] == "blocks"
    assert summary["skipped_rows"] == {"image_missing": 1}
    base = json.loads((out / "base" / "config.json").read_text(encoding="utf-8"))
    assert base["split"] == "blocks" and base["model"] == "fast" and base["epochs"] == 1
    config = json.loads((out / "config.json").read_text(encoding="utf-8"))
    assert config["split"] == "blocks" and config["epochs"] == finetune_epochs
    assert not (out / "model.h5").exists() and (out / "model.keras").is_file()
    # Nothing to train on is a clear error, not a traceback.
    assert main(["train", "--out", str(tmp_path / "empty")]) == 1
    assert "nothing to train on" in capsys.readouterr().err


def test_early_stopping_counts_epochs_since_the_best(tmp_path: Path) -> None:
    config = dataclasses.replace(FAST, early_stopping_patience=2)
    history = [
        {"epoch": 1, "val_loss": 0.5}, {"epoch": 2, "val_loss": 0.3}, {"epoch": 3, "val_loss": 0.4}
    ]
    recorder = run_recorder_class()(tmp_path, config, history, {})
    assert recorder.best_epoch() == (2, 0.3) and not recorder.should_stop()
    history.append({"epoch": 4, "val_loss": 0.35})
    assert run_recorder_class()(tmp_path, config, history, {}).should_stop()
    assert not run_recorder_class()(tmp_path, FAST, history, {}).should_stop()


@pytest.mark.slow
def test_training_logs_one_line_per_epoch_when_not_on_a_terminal(damaged_recordings,
                                                                  tmp_path: Path) -> None:
    """Output to a file or pipe gets Keras's one line per epoch, not the progress bar's frames."""
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", "clonedrive", "train", *map(str, damaged_recordings), "--recipe",
         "writeup", "--epochs", "2", "--batch-size", "128", "--no-h5", "--out",
         str(tmp_path / "r")],
        capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    output = done.stdout + done.stderr
    epoch_lines = [line for line in output.splitlines() if " - loss: " in line]
    assert len(epoch_lines) == 2  # one per epoch
    assert all("val_loss" in line for line in epoch_lines)
    assert "━" not in output  # no bar frames


def test_a_missing_input_is_named_before_keras_loads(tmp_path: Path) -> None:
    """A folder or recipe that does not exist fails at once, in a process that never imports
    Keras."""
    import subprocess
    import sys

    probe = ("import sys; from clonedrive.cli import main; code = main(sys.argv[1:]); "
             "assert 'keras' not in sys.modules; sys.exit(code)")
    for argv, says in (([str(tmp_path / "nowhere"), "--out", str(tmp_path / "r")],
                        "no driving log at"),
                       (["--recipe", str(tmp_path / "r.toml"), "--out", str(tmp_path / "r")],
                        "recipe not found")):
        done = subprocess.run([sys.executable, "-c", probe, "train", *argv],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 1, done.stderr
        assert done.stderr.startswith(f"clonedrive train: {says}")
    assert not (tmp_path / "r").exists()


def test_the_shift_augmentations_steering_gain_comes_from_the_config(
    damaged_recordings, tmp_path: Path
) -> None:
    from clonedrive.data.dataset import build_dataset
    from clonedrive.data.recipe import default_recipe_for
    from clonedrive.model.architectures import build_model
    from clonedrive.model.train import _batches

    recipe = default_recipe_for(damaged_recordings)
    model = build_model("fast", seed=0)

    def label_sizes(gain: float) -> tuple[np.ndarray, np.ndarray]:
        """(|training labels| of the first batch, |its samples' own labels|)."""
        config = dataclasses.replace(FAST, shift_steering_per_px=gain)
        data = build_dataset(recipe, config.dataset_config(), tmp_path / f"run{gain}",
                             progress=False)
        try:
            train_batches, _ = _batches(config, data, model, 0)
            _, labels = train_batches[0]
            own = data.train.steering[train_batches.batch_indices(0)]
            return np.abs(labels), np.abs(own)
        finally:
            data.close()

    labels, own = label_sizes(0.0)  # no gain: a shifted picture keeps its label (or its mirror)
    np.testing.assert_allclose(labels, own, atol=1e-6)
    labels, own = label_sizes(0.004)
    assert np.mean(np.abs(labels - own) > 1e-3) > 0.5  # most labels moved with their shift

    with pytest.raises(ValueError, match=r"shift_steering_per_px must be in \[0, 0.02\]"):
        dataclasses.replace(FAST, shift_steering_per_px=float("nan"))
