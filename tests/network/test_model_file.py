"""Model files: what is refused and how it is said; students' Lambda models with --trust-model;
the outputs a steering model may have; NaN predictions counted."""

from __future__ import annotations

import json
import logging
import marshal
import zipfile
from pathlib import Path

import cv2
import h5py
import keras
import numpy as np
import pytest
from keras import layers
from support.student_models import (
    python36_lambda_code,
    student_model,
    this_python_lambda_code,
    write_keras1_h5,
    write_keras2_h5,
)

from clonedrive.drivers.policy import NetworkPolicy, load_policy
from clonedrive.network import legacy_keras, model_file
from clonedrive.network.model_file import load_model
from clonedrive.network.tiny_model import build_tiny_model

FIXTURE = Path(__file__).parents[1] / "fixtures" / "udacity" / "lake_posix_mixed_columns"


@pytest.fixture(scope="module")
def real_frames() -> np.ndarray:
    """Eight real Udacity centre frames, RGB uint8."""
    paths = sorted((FIXTURE / "IMG").glob("center_*.jpg"))[::9][:8]
    return np.stack([cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB) for path in paths])


@pytest.fixture(scope="module")
def student() -> keras.Model:
    return student_model(seed=4)


def predictions(model, frames: np.ndarray) -> np.ndarray:
    return np.asarray(model.predict_on_batch(frames.astype(np.float32))).reshape(-1)


# --------------------------------------------------------------------------- not a model


def test_a_random_file_named_model_keras_is_not_a_keras_model_file(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    for name in ("model.keras", "model.h5"):
        path = tmp_path / name
        path.write_bytes(rng.integers(0, 256, 4096, dtype=np.uint8).tobytes())
        with pytest.raises(ValueError, match=rf"{name}: not a Keras model file") as caught:
            load_model(path)
        assert "not found" not in str(caught.value)


def test_other_files_that_are_not_models(tmp_path: Path, student) -> None:
    (tmp_path / "empty.keras").write_bytes(b"")
    with pytest.raises(ValueError, match="empty.keras: empty file"):
        load_model(tmp_path / "empty.keras")
    (tmp_path / "folder.keras").mkdir()
    with pytest.raises(ValueError, match="folder.keras: not a file"):
        load_model(tmp_path / "folder.keras")
    with pytest.raises(FileNotFoundError, match="missing.keras"):
        load_model(tmp_path / "missing.keras")
    with zipfile.ZipFile(tmp_path / "archive.keras", "w") as archive:
        archive.writestr("readme.txt", "hello")
    with pytest.raises(ValueError, match=r"archive.keras: not a Keras model file \(a zip archive "
                                         r"without config.json\)"):
        load_model(tmp_path / "archive.keras")
    build_tiny_model().save(tmp_path / "real.h5")
    (tmp_path / "real.h5").rename(tmp_path / "renamed.keras")
    with pytest.raises(ValueError, match="renamed.keras: an HDF5 model file named .keras"):
        load_model(tmp_path / "renamed.keras")
    build_tiny_model().save(tmp_path / "real.keras")
    (tmp_path / "real.keras").rename(tmp_path / "renamed.h5")
    with pytest.raises(ValueError, match="renamed.h5: a Keras 3 .keras archive named .h5"):
        load_model(tmp_path / "renamed.h5")
    with h5py.File(tmp_path / "weights.h5", "w") as handle:
        handle.create_dataset("kernel", data=np.zeros(3))
    with pytest.raises(ValueError, match="weights.h5: an HDF5 file without a model config"):
        load_model(tmp_path / "weights.h5")
    with pytest.raises(ValueError, match="runtime 'gpu'"):
        load_model(tmp_path / "real.h5", runtime="gpu")


def test_model_file_size_is_bounded(tmp_path: Path) -> None:
    path = tmp_path / "huge.keras"
    with open(path, "wb") as handle:  # sparse: nothing is written or read
        handle.truncate(model_file.MAX_MODEL_BYTES + 1)
    with pytest.raises(ValueError, match=r"huge.keras: 2.0 GiB is over the 2 GiB limit"):
        load_model(path)


# --------------------------------------------------------------------------- outputs


def two_headed(names: tuple[str, ...], units: int = 1) -> keras.Model:
    inputs = keras.Input(shape=(160, 320, 3))
    pooled = layers.GlobalAveragePooling2D()(inputs)
    outputs = [layers.Dense(units, name=name)(pooled) for name in names]
    return keras.Model(inputs, outputs if len(outputs) > 1 else outputs[0])


def test_outputs_are_checked_at_load(tmp_path: Path) -> None:
    for names, units, message in [
        (("steering", "throttle"), 1, r"two outputs \(steering, throttle\); a second output "
                                      r"must be named 'target_speed'"),
        (("target_speed", "steering"), 1, r"must be named 'target_speed'"),
        (("steering", "target_speed", "brake"), 1, "3 outputs"),
        (("steering",), 2, r"'steering' output has shape \(2,\)"),
    ]:
        path = tmp_path / f"{'_'.join(names)}_{units}.keras"
        two_headed(names, units).save(path)
        with pytest.raises(ValueError, match=message) as caught:
            load_model(path)
        assert str(caught.value).startswith(str(path))
    # The hook for a speed head: steering, then a named target_speed output.
    path = tmp_path / "speed_head.keras"
    two_headed(("steering", "target_speed")).save(path)
    policy = load_policy(path)
    steering, _ = policy.act(np.zeros((160, 320, 3), np.uint8), 0.0)
    assert isinstance(steering, float)


def test_nan_predictions_are_counted() -> None:
    inputs = keras.Input(shape=(160, 320, 3))
    pooled = layers.GlobalAveragePooling2D()(inputs)
    outputs = layers.Dense(1, name="steering")(pooled)
    model = keras.Model(inputs, outputs)
    model.layers[-1].set_weights([np.zeros((3, 1), np.float32), np.array([np.nan], np.float32)])
    policy = NetworkPolicy(model)
    frames = np.zeros((5, 160, 320, 3), np.uint8)
    assert policy.nan_predictions == 0
    assert policy.act(frames[0], 0.0)[0] == 0.0
    assert policy.nan_predictions == 1
    np.testing.assert_array_equal(policy.predict_steering(frames), np.zeros(5))
    assert policy.nan_predictions == 6
    assert policy.last_nonfinite.tolist() == [True] * 5


def test_evaluate_counts_nan_predictions_per_run_in_eval_json(tmp_path: Path) -> None:
    from clonedrive.evaluate.results import format_table
    from clonedrive.evaluate.rollout import EvalConfig, evaluate

    inputs = keras.Input(shape=(160, 320, 3))
    outputs = layers.Dense(1, name="steering")(layers.GlobalAveragePooling2D()(inputs))
    model = keras.Model(inputs, outputs)
    model.layers[-1].set_weights([np.zeros((3, 1), np.float32), np.array([np.nan], np.float32)])
    config = EvalConfig(tracks=("lake", "mountain"), speeds_mph=(9.0,), laps=1, scenery=False,
                        max_seconds=1.0, workers=1)
    report = evaluate(NetworkPolicy(model), config, tmp_path, progress=False)
    on_disk = json.loads((tmp_path / "eval.json").read_text(encoding="utf-8"))
    # Two cars in lock-step for 1 s at 15 Hz: every one of each car's 15 frames was NaN.
    assert [run["nan_predictions"] for run in on_disk["runs"]] == [15, 15]
    assert "predicted NaN or infinite steering on 15 frame(s)" in format_table(report)


# --------------------------------------------------------------------------- students' models


def test_keras3_saved_student_h5_needs_trust(tmp_path: Path, student, real_frames, caplog) -> None:
    path = tmp_path / "model.h5"
    student.save(path)
    with pytest.raises(ValueError, match=r"Lambda layers \(lambda_1\).*--trust-model"):
        load_model(path)
    with caplog.at_level(logging.WARNING, logger="clonedrive.model"):
        model = load_model(path, trust=True)
    assert "WARNING: --trust-model" in caplog.text and "lambda_1" in caplog.text
    np.testing.assert_allclose(predictions(model, real_frames), predictions(student, real_frames),
                               atol=1e-6)


def test_keras2_student_h5_from_python36_is_rebuilt(tmp_path: Path, student, real_frames,
                                                    caplog) -> None:
    path = write_keras2_h5(tmp_path / "model.h5", student)
    with pytest.raises(ValueError, match="--trust-model"):
        load_model(path)
    why = legacy_keras.probe_lambdas(model_file.model_config(path, "hdf5")[0])
    assert isinstance(why, str) and why  # Python 3.6 bytecode does not run here: a reason
    with caplog.at_level(logging.WARNING, logger="clonedrive.model"):
        model = load_model(path, trust=True)
    assert "does not run on Python" in caplog.text
    assert "lambda_1 -> Rescaling (x / 255 - 0.5)" in caplog.text
    assert "weights of 9 layers loaded by name" in caplog.text
    np.testing.assert_allclose(predictions(model, real_frames), predictions(student, real_frames),
                               atol=1e-5)


def test_keras2_student_h5_whose_code_runs_here(tmp_path: Path, student, real_frames,
                                                caplog) -> None:
    # The code runs on this Python, so Keras 3's own loader is tried; it cannot read a Keras 2
    # Sequential (batch_input_shape on the first layer), so the rebuild takes over.
    path = write_keras2_h5(tmp_path / "model.h5", student, lambda_code=this_python_lambda_code())
    assert legacy_keras.probe_lambdas(model_file.model_config(path, "hdf5")[0]) is None
    with caplog.at_level(logging.WARNING, logger="clonedrive.model"):
        model = load_model(path, trust=True)
    assert "does not run" not in caplog.text
    assert "Keras 3 could not load it as saved" in caplog.text
    np.testing.assert_allclose(predictions(model, real_frames), predictions(student, real_frames),
                               atol=1e-6)


def test_keras1_student_h5_is_rebuilt(tmp_path: Path, student, real_frames) -> None:
    path = write_keras1_h5(tmp_path / "model.h5", student)
    model = load_model(path, trust=True)
    assert [layer.name for layer in model.layers][2:4] == ["cropping2d_1", "convolution2d_1"]
    np.testing.assert_allclose(predictions(model, real_frames), predictions(student, real_frames),
                               atol=1e-5)


def test_a_lambda_that_does_more_than_scale_is_not_guessed(tmp_path: Path, student,
                                                            real_frames) -> None:
    code = python36_lambda_code(names=("tf", "image", "resize_images"))
    path = write_keras2_h5(tmp_path / "model.h5", student, lambda_code=code)
    with pytest.raises(ValueError, match=r"Lambda 'lambda_1' uses image, resize_images, tf.*"
                                         r"docs/udacity.md"):
        load_model(path, trust=True)
    # The documented way out: say what the Lambda computes.
    model = legacy_keras.rebuild(path, normalisation=(1 / 255.0, -0.5))
    np.testing.assert_allclose(predictions(model, real_frames), predictions(student, real_frames),
                               atol=1e-5)


def test_constants_are_read_from_bytecode_of_any_python() -> None:
    assert {255.0, 0.5} <= legacy_keras.code_constants(python36_lambda_code())
    assert {255.0, 0.5} <= legacy_keras.code_constants(this_python_lambda_code())
    other = marshal.dumps((lambda x: x / 127.5 - 1.0).__code__)
    assert legacy_keras.code_constants(other) >= {127.5, 1.0}
