"""The open-loop crosscheck on real Udacity logs: its figures against hand computation, an
oracle and constant policies, segments, centre-only logs and the command."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from clonedrive.base.images import read_rgb
from clonedrive.cli import main
from clonedrive.evaluate.crosscheck import CrosscheckConfig, correlation, crosscheck, smooth

FIXTURES = Path(__file__).parents[1] / "fixtures" / "udacity"
LAKE = FIXTURES / "lake_posix_mixed_columns"  # 70 rows in three time segments
MOUNTAIN = FIXTURES / "mountain_windows_paths"  # 70 consecutive rows, keyboard steering


class TablePolicy:
    """Answers each frame from a table: the human's steering (an oracle) or a constant."""

    def __init__(self, log: Path, constant: float | None = None) -> None:
        from clonedrive.data.driving_log import read_driving_log

        self.constant = constant
        self.table = {read_rgb(row.center).tobytes(): row.steering
                      for row in read_driving_log(log).rows}
        self.calls = 0

    def predict_steering(self, frames: np.ndarray) -> np.ndarray:
        self.calls += 1
        if self.constant is not None:
            return np.full(len(frames), self.constant, np.float32)
        return np.array([self.table[frame.tobytes()] for frame in frames], np.float32)


def test_smoothing_stays_inside_segments() -> None:
    values = np.array([0.0, 0.0, 3.0, 0.0, 0.0, 9.0, 9.0])
    segments = np.array([0, 0, 0, 0, 0, 1, 1])
    np.testing.assert_allclose(smooth(values, 3, segments),
                               [0.0, 1.0, 1.0, 1.0, 0.0, 9.0, 9.0])
    np.testing.assert_allclose(smooth(values, 1, segments), values)
    assert correlation(np.ones(5), np.arange(5.0)) is None
    assert correlation(np.arange(5.0), 2 * np.arange(5.0) + 1) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="odd"):
        CrosscheckConfig(smoothing_frames=4)


def test_an_oracle_and_the_baselines(tmp_path: Path) -> None:
    oracle = crosscheck(TablePolicy(MOUNTAIN), MOUNTAIN, tmp_path / "oracle",
                        CrosscheckConfig(batch_size=16))
    human = np.array([row["human"] for row in _rows(tmp_path / "oracle")])
    assert oracle["rows"] == 70 and oracle["segments"] == 1
    assert oracle["rmse"] == pytest.approx(0.0, abs=1e-6)
    assert oracle["correlation_raw"] == pytest.approx(1.0)
    assert 0.8 < oracle["correlation"] < 1.0  # against the smoothed trace
    assert oracle["rmse_zero"] == pytest.approx(np.sqrt(np.mean(human ** 2)), abs=1e-4)
    assert oracle["rmse_mean"] == pytest.approx(np.std(human), abs=1e-4)
    constant = crosscheck(TablePolicy(MOUNTAIN, constant=0.0), MOUNTAIN, tmp_path / "zero")
    assert constant["rmse"] == pytest.approx(oracle["rmse_zero"], abs=1e-4)
    assert constant["correlation"] is None
    for name in ("crosscheck.json", "crosscheck.csv", "crosscheck.png"):
        assert (tmp_path / "zero" / name).is_file()
    assert json.loads((tmp_path / "zero" / "crosscheck.json").read_text())["rows"] == 70


def test_gaps_in_the_log_split_segments(tmp_path: Path) -> None:
    report = crosscheck(TablePolicy(LAKE), LAKE, tmp_path)
    assert report["segments"] == 3
    assert report["seconds"] < 10.0  # the driving, not the hour between the slices


def test_a_centre_only_log(tmp_path: Path) -> None:
    log = tmp_path / "centre_only"
    (log / "IMG").mkdir(parents=True)
    shutil.copy(MOUNTAIN / "driving_log.csv", log / "driving_log.csv")
    for image in (MOUNTAIN / "IMG").glob("center_*.jpg"):
        shutil.copy(image, log / "IMG" / image.name)
    report = crosscheck(TablePolicy(MOUNTAIN), log, tmp_path / "out")
    assert report["rows"] == 70 and report["rmse"] == pytest.approx(0.0, abs=1e-6)


def _rows(folder: Path) -> list[dict]:
    import csv

    with open(folder / "crosscheck.csv", encoding="utf-8") as handle:
        return [{key: float(value) for key, value in row.items()} for row in csv.DictReader(handle)]


def test_the_command(tmp_path: Path, tiny_model_path: Path, capsys) -> None:
    out = tmp_path / "cc"
    assert main(["crosscheck", str(tiny_model_path), str(MOUNTAIN), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "RMSE" in printed and "always 0" in printed
    assert json.loads((out / "crosscheck.json").read_text())["rows"] == 70
    assert main(["crosscheck", str(tiny_model_path), str(tmp_path / "nothing"),
                 "--out", str(tmp_path / "x")]) == 1
    assert main(["crosscheck", str(tiny_model_path), str(MOUNTAIN), "--smooth", "4",
                 "--out", str(tmp_path / "y")]) == 2
    err = capsys.readouterr().err
    assert "no driving log" in err and "odd" in err and "Traceback" not in err


def test_nan_predictions_are_counted_not_hidden(tmp_path: Path) -> None:
    """A network whose steering is NaN: crosscheck says how often, as evaluate does."""
    import keras
    from keras import layers

    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.evaluate.crosscheck import format_summary

    inputs = keras.Input(shape=(160, 320, 3))
    model = keras.Model(inputs, layers.Dense(1, name="steering")(
        layers.GlobalAveragePooling2D()(inputs)))
    model.layers[-1].set_weights([np.zeros((3, 1), np.float32), np.array([np.nan], np.float32)])
    report = crosscheck(NetworkPolicy(model), MOUNTAIN, tmp_path / "nan", CrosscheckConfig())
    assert report["nan_predictions"] == report["rows"] > 0
    assert f"{report['rows']} prediction(s) were NaN or infinite" in format_summary(report)
    written = json.loads((tmp_path / "nan" / "crosscheck.json").read_text())
    assert written["nan_predictions"] == report["rows"]
