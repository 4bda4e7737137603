"""A model whose steering is NaN is refused when a command loads it (a probe frame), unless
``--allow-nan-model`` says to drive it anyway; crosscheck then counts its NaN predictions."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from clonedrive.cli import main

MOUNTAIN = Path(__file__).parents[1] / "fixtures" / "udacity" / "mountain_windows_paths"


@pytest.fixture(scope="module")
def nan_model_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    import keras
    from keras import layers

    inputs = keras.Input(shape=(160, 320, 3))
    model = keras.Model(inputs, layers.Dense(1, name="steering")(
        layers.GlobalAveragePooling2D()(inputs)))
    model.layers[-1].set_weights([np.zeros((3, 1), np.float32), np.array([np.nan], np.float32)])
    path = tmp_path_factory.mktemp("nan") / "nan.keras"
    model.save(path)
    return path


def test_a_nan_model_is_refused_at_load(nan_model_path: Path, tmp_path: Path, capsys) -> None:
    status = main(["evaluate", str(nan_model_path), "--track", "lake", "--laps", "1",
                   "--out", str(tmp_path / "eval")])
    err = capsys.readouterr().err
    assert status == 2
    assert err == (f"clonedrive evaluate: {nan_model_path}: the model's steering is NaN or "
                   "infinite on a probe frame (its weights hold NaN?); --allow-nan-model "
                   "drives it anyway\n")
    assert not (tmp_path / "eval").exists()


def test_allowed_it_is_driven_and_its_nan_predictions_counted(nan_model_path: Path,
                                                              tmp_path: Path, capsys) -> None:
    out = tmp_path / "cross"
    status = main(["crosscheck", str(nan_model_path), str(MOUNTAIN), "--out", str(out),
                   "--allow-nan-model", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert status == 0
    assert report["nan_predictions"] == report["rows"] > 0
