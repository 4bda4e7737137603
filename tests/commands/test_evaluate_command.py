"""``clonedrive evaluate`` through the CLI: a model that holds the steering of a circular track
drives it in closed loop; eval.json, the map and the printed figures agree."""

from __future__ import annotations

import io
import json
import math
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest

from clonedrive.base.udacity_spec import IMAGE_SHAPE, MAX_WHEEL_ANGLE_DEG
from clonedrive.cli import main
from clonedrive.world.vehicle import VehicleParams

RADIUS_M = 30.0


def circle_track(path: Path, radius_m: float = RADIUS_M) -> Path:
    """A flat counter-clockwise circle (left turns all the way), 8 m wide."""
    angles = [2 * math.pi * i / 24 for i in range(24)]
    path.write_text(json.dumps({
        "name": "circle", "version": 1, "theme": "lake", "width_m": 8.0, "closed": True,
        "centerline": [[radius_m * math.cos(a), radius_m * math.sin(a), 0.0] for a in angles],
    }))
    return path


def constant_steering_model(path: Path, steering: float) -> Path:
    """A model that ignores the picture and always answers ``steering``."""
    import keras

    inputs = keras.Input(shape=IMAGE_SHAPE)
    x = keras.layers.GlobalAveragePooling2D()(inputs)
    output = keras.layers.Dense(1, kernel_initializer="zeros", name="steering")
    model = keras.Model(inputs, output(x))
    output.set_weights([np.zeros((3, 1), np.float32), np.array([steering], np.float32)])
    model.save(path)
    return path


@pytest.fixture(scope="module")
def circle_run(tmp_path_factory) -> tuple[int, dict, Path, Path]:
    folder = tmp_path_factory.mktemp("evaluate")
    vehicle = VehicleParams()
    wheelbase_m = vehicle.l_f + vehicle.l_r
    # Left (negative) steering that holds the circle: the kinematic angle, plus 5 % for the
    # understeer of the tyre model at 15 mph.
    steering = -1.05 * math.degrees(math.atan(wheelbase_m / RADIUS_M)) / MAX_WHEEL_ANGLE_DEG
    model = constant_steering_model(folder / "circle.keras", steering)
    track = circle_track(folder / "circle.json")
    out = folder / "eval"
    printed = io.StringIO()
    with redirect_stdout(printed):
        code = main(["evaluate", str(model), "--track", str(track), "--speed", "15",
                     "--laps", "1", "--json", "--out", str(out)])
    return code, json.loads(printed.getvalue()), out, track


def test_a_model_that_holds_the_circle_completes_the_lap(circle_run):
    code, report, _, track = circle_run
    assert code == 0
    (run,) = report["runs"]
    assert run["track"] == str(track) and run["speed_mph"] == 15.0
    assert run["laps_completed"] == 1 and run["interventions"] == 0
    assert run["autonomy_pct"] == 100.0 and not run["timed_out"]
    assert run["max_abs_cte_m"] < 2.5  # measured 1.4: well inside the 4 m half width
    assert run["distance_m"] == pytest.approx(2 * math.pi * RADIUS_M, rel=0.1)


def test_eval_json_and_the_map_are_written_inside_out(circle_run):
    _, report, out, _ = circle_run
    assert json.loads((out / "eval.json").read_text()) == report
    (run,) = report["runs"]
    map_png = out / run["map_png"]
    assert map_png.name == "circle_15mph_map.png"  # named after the track, not its path
    assert map_png.is_file() and out.resolve() in map_png.resolve().parents
    assert (out / "config.json").is_file()


def test_a_missing_model_is_one_line(tmp_path, capsys):
    code = main(["evaluate", str(tmp_path / "none.keras"), "--out", str(tmp_path / "eval")])
    err = capsys.readouterr().err
    assert code != 0 and "none.keras" in err and len(err.strip().splitlines()) == 1
