"""``clonedrive train`` takes its settings from a recipe (best by default), writes the recipe's
driving settings into every model file, and ``evaluate`` drives the model with them."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clonedrive.cli import main
from clonedrive.network.driving_settings import DrivingSettings, read_notes, stored_settings

REPOSITORY = Path(__file__).resolve().parents[2]
LAKE = Path(__file__).resolve().parents[1] / "fixtures" / "udacity" / "lake_posix_mixed_columns"


@pytest.fixture(scope="module")
def best_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("train") / "best"
    assert main(["train", str(LAKE), "--epochs", "1", "--batch-size", "64", "--out", str(out),
                 "--json"]) == 0
    return out


def test_train_without_a_recipe_uses_best_and_stores_how_to_drive(best_run: Path):
    config = json.loads((best_run / "config.json").read_text())
    assert config["speed_head"] is True and config["crop_top_px"] == 60
    assert config["correction"] == 0.054 and config["balance"] is False
    notes = read_notes(best_run / "model.keras")
    assert notes["recipe"]["name"] == "best"
    assert stored_settings(best_run / "model.keras") == DrivingSettings(
        mirror_average=True, steering_hold=0.004, steering_filter_s=0.05, full_speed_at=0.95,
        caution=40.0, caution_from=0.015)
    assert stored_settings(best_run / "last.keras") == stored_settings(best_run / "model.keras")


def test_model_h5_has_one_output_for_udacitys_drive_py(best_run: Path):
    """drive.py calls ``float(model.predict(image[None], batch_size=1))``: one output."""
    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()
    model = keras.saving.load_model(best_run / "model.h5", compile=False)
    prediction = model.predict(np.zeros((1, 160, 320, 3), np.float32), batch_size=1, verbose=0)
    assert np.asarray(prediction).shape == (1, 1)
    assert isinstance(float(np.asarray(prediction)[0, 0]), float)
    assert stored_settings(best_run / "model.h5").mirror_average is True


def test_evaluate_with_no_flags_drives_as_the_model_file_says(best_run: Path, tmp_path: Path):
    out = tmp_path / "eval"
    assert main(["evaluate", str(best_run / "model.keras"), "--track", "lake", "--speed", "30",
                 "--laps", "1", "--max-seconds", "2", "--no-scenery", "--workers", "1",
                 "--out", str(out), "--json"]) == 0
    header = json.loads((out / "eval.json").read_text())
    assert header["mirror_average"] is True and header["steering_hold"] == 0.004
    assert header["steering_filter_s"] == 0.05
    assert header["speed_head"] is True and header["slow_in_curves"] is False
    assert header["recipe"] == {"name": "best", "version": 8}
    assert header["steering_scale_from_mph"] == 0.0
    assert header["speed_scale"] == 1.0
    assert header["full_speed_at"] == 0.95
    assert "full speed from 0.95 of the set speed" in header["speed_control"]
    # Options given override the file one by one.
    out = tmp_path / "eval2"
    assert main(["evaluate", str(best_run / "model.keras"), "--track", "lake", "--laps", "1",
                 "--max-seconds", "2", "--no-scenery", "--workers", "1", "--out", str(out),
                 "--no-mirror-average", "--slow-in-curves", "--steering-scale-from", "24",
                 "--json"]) == 0
    header = json.loads((out / "eval.json").read_text())
    assert header["mirror_average"] is False and header["steering_hold"] == 0.004
    assert header["slow_in_curves"] is True and header["steering_scale_from_mph"] == 24.0


def test_train_with_the_writeup_recipe(tmp_path: Path):
    out = tmp_path / "writeup"
    assert main(["train", str(LAKE), "--recipe", "writeup", "--epochs", "1", "--no-h5",
                 "--out", str(out), "--json"]) == 0
    config = json.loads((out / "config.json").read_text())
    assert config["speed_head"] is False and config["crop_top_px"] == 80
    assert config["correction"] == 0.2 and config["batch_size"] == 128
    assert stored_settings(out / "model.keras") == DrivingSettings(slow_in_curves=True)


def test_a_recipe_that_records_its_data_needs_a_data_folder(tmp_path: Path, capsys):
    assert main(["train", "--recipe", "best", "--out", str(tmp_path / "x")]) == 1
    assert "--data FOLDER" in capsys.readouterr().err
    assert main(["train", "--recipe", "best", "--data", str(tmp_path / "nowhere"),
                 "--out", str(tmp_path / "y")]) == 1
    assert "no such folder" in capsys.readouterr().err


def test_a_recipe_with_a_finetune_trains_two_stages(tmp_path: Path):
    """[finetune] is a second stage from the first one's best model; OUT/model.keras is it."""
    from importlib import resources

    text = resources.files("clonedrive.recipes").joinpath("best.toml").read_text("utf-8")
    text = text.replace('name = "best"', 'name = "staged"')
    start, end = text.index("[[finetune]]"), text.index("[drive]")  # one [finetune] table
    text = (text[:start] + "[finetune]\nepochs = 1\nlearning_rate = 0.0003\nconsistency = 10\n\n"
            + text[end:])
    recipe = tmp_path / "staged.toml"
    recipe.write_text(text, encoding="utf-8")
    out = tmp_path / "run"
    assert main(["train", str(LAKE), "--recipe", str(recipe), "--epochs", "1",
                 "--batch-size", "64", "--no-h5", "--out", str(out), "--json"]) == 0
    base = json.loads((out / "base" / "config.json").read_text())
    final = json.loads((out / "config.json").read_text())
    assert base["epochs"] == 1 and base["consistency"] == 0
    assert final["init_from"] == str(out / "base" / "model.keras")
    assert final["consistency"] > 0 and final["learning_rate"] < base["learning_rate"]
    assert read_notes(out / "model.keras")["recipe"]["name"] == "staged"
    # Training again into the same folder is refused, as for one stage.
    assert main(["train", str(LAKE), "--recipe", str(recipe), "--epochs", "1",
                 "--out", str(out)]) == 1


def test_recipe_best_trains_three_stages_each_from_the_one_before(best_run: Path):
    """[[finetune]] tables: one stage each; the stage between trains into stage2/."""
    base, middle, final = (json.loads((folder / "config.json").read_text())
                           for folder in (best_run / "base", best_run / "stage2", best_run))
    assert middle["init_from"] == str(best_run / "base" / "model.keras")
    assert final["init_from"] == str(best_run / "stage2" / "model.keras")
    assert [config["consistency"] for config in (base, middle, final)] == [0, 60, 60]
    assert [config["epochs"] for config in (base, middle, final)] == [1, 2, 1]
    assert [config["batch_size"] for config in (base, middle, final)] == [64, 64, 64]
    assert read_notes(best_run / "model.keras")["recipe"] == {"name": "best", "version": 8}


def test_a_finetune_reuses_the_first_stages_images_and_trains_the_same_model(
        tmp_path: Path, capsys):
    """The second stage takes the first one's decoded images (here a memmap) instead of
    decoding them again; the model is the one two separate stages make, and no cache file is
    left."""
    import dataclasses

    from clonedrive.model.train import train
    from clonedrive.network.model_file import load_model
    from clonedrive.recipes.book import load_recipe_file
    from clonedrive.recipes.training import run_stages, train_stages

    recipe = load_recipe_file("best")
    stages = [dataclasses.replace(config, epochs=1, batch_size=64, cache="memmap",
                                  export_h5=False) for config in train_stages(recipe)[:2]]
    assert len(stages) == 2
    data = recipe.folders_recipe([LAKE])
    run_stages(stages, data, tmp_path / "shared", progress=True)
    printed = capsys.readouterr().out
    assert printed.count("(the previous stage's, reused)") == 1
    assert not list((tmp_path / "shared").rglob("image_cache.u8"))
    # The same two stages, each decoding its own images.
    train(stages[0], data, tmp_path / "apart" / "base", progress=False)
    second = dataclasses.replace(stages[1],
                                 init_from=str(tmp_path / "apart" / "base" / "model.keras"))
    train(second, data, tmp_path / "apart", progress=False)
    shared = load_model(tmp_path / "shared" / "model.keras").get_weights()
    apart = load_model(tmp_path / "apart" / "model.keras").get_weights()
    assert len(shared) == len(apart)
    assert all(np.array_equal(a, b) for a, b in zip(shared, apart, strict=True))


def test_a_recipe_s_driving_settings_do_not_change_what_it_trains(best_run: Path,
                                                                  tmp_path: Path):
    """A recipe that differs only in [drive] trains the same weights to the bit, so a model's
    driving settings can be compared on one trained network."""
    from importlib import resources

    from clonedrive.network.model_file import load_model

    text = resources.files("clonedrive.recipes").joinpath("best.toml").read_text("utf-8")
    assert "caution_from = 0.015" in text
    copy = tmp_path / "other.toml"
    copy.write_text(text.replace("caution_from = 0.015", "caution_from = 0.03"))
    out = tmp_path / "other"
    assert main(["train", str(LAKE), "--recipe", str(copy), "--epochs", "1", "--batch-size",
                 "64", "--out", str(out), "--json"]) == 0
    assert stored_settings(out / "model.keras").caution_from == 0.03
    ours, theirs = (load_model(run / "model.keras") for run in (best_run, out))
    for a, b in zip(ours.get_weights(), theirs.get_weights(), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def _udacity_page_example() -> str:
    """The plain-Python loading example of docs/udacity.md ("Our models outside clonedrive")."""
    text = (Path(__file__).resolve().parents[2] / "docs" / "udacity.md").read_text("utf-8")
    section = text[text.index("**Our models outside clonedrive.**"):]
    return re.search(r"^```python\n(.*?)^```", section, flags=re.S | re.M).group(1)


def test_the_model_loads_in_plain_keras_as_the_docs_show(best_run: Path, tmp_path: Path):
    """The default recipe's model (fine-tuned with the ConsistentMSE loss) loads with
    safe_mode in a process that never imports clonedrive, and answers a frame."""
    code = _udacity_page_example().replace("runs/x/model.keras",
                                           str(best_run / "model.keras"))
    code += "\nimport sys\nassert 'clonedrive' not in sys.modules, 'clonedrive was imported'\n"
    env = {**os.environ, "KERAS_BACKEND": "torch", "PYTHONPATH": ""}
    done = subprocess.run([sys.executable, "-I", "-c", code], cwd=REPOSITORY, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert re.fullmatch(r"steering [+-]\d\.\d{3} \(wheel / 25 deg\), target speed \d\.\d\d of "
                        r"top speed\n", done.stdout), done.stdout


def test_stages_1_trains_the_first_stage_alone_and_the_plan_says_so(tmp_path: Path, capsys):
    out = tmp_path / "one"
    assert main(["train", str(LAKE), "--epochs", "1", "--stages", "1", "--batch-size", "64",
                 "--no-h5", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    plan = printed[printed.index("[plan]"):].splitlines()[:2]
    assert plan == ["[plan] 1 stage(s), 1 epoch(s) in all:",
                    "  stage 1: fast, 1 epoch(s) from scratch, learning rate 0.001"]
    assert not (out / "base").exists()
    assert len((out / "history.csv").read_text().splitlines()) == 2  # header + one epoch


def test_the_plan_of_best_shows_the_fine_tunes_epochs():
    from clonedrive.commands.train import plan_text
    from clonedrive.recipes.book import load_recipe_file
    from clonedrive.recipes.training import train_stages

    text = plan_text(train_stages(load_recipe_file("best"), epochs=1))
    assert text.splitlines() == [
        "[plan] 3 stage(s), 4 epoch(s) in all:",
        "  stage 1: fast, 1 epoch(s) from scratch, learning rate 0.001",
        "  stage 2: fast, 2 epoch(s) from the stage before, learning rate 0.0005, "
        "consistency 60",
        "  stage 3: fast, 1 epoch(s) from the stage before, learning rate 0.0005, "
        "consistency 60"]


@pytest.mark.parametrize("stages", ["0", "4"])
def test_stages_beyond_the_recipe_are_refused(stages: str, tmp_path: Path, capsys):
    assert main(["train", str(LAKE), "--stages", stages, "--out", str(tmp_path / "x")]) == 2
    assert f"--stages {stages}: recipe best has 3 stage(s); give 1 to 3" in \
        capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_a_folder_of_recordings_is_refused_with_the_recordings_named(tmp_path: Path, capsys):
    data = tmp_path / "data"
    (data / "middle").mkdir(parents=True)
    (data / "middle" / "driving_log.csv").write_text("", encoding="utf-8")
    out = tmp_path / "runs" / "y"
    assert main(["train", str(data), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert f"no driving log in {data}: it holds recordings; give them: clonedrive train " \
           f"{data / 'middle'}" in err
    assert not out.exists()  # refused before anything was made


def test_balancing_off_writes_one_histogram_without_a_target(best_run: Path):
    """best keeps every sample: one histogram of the labels, not a before and an identical
    after with a target line that nothing was balanced to."""
    for stage in ("base", "stage2"):
        assert (best_run / stage / "steering_before.png").is_file()
        assert not (best_run / stage / "steering_after.png").exists()
    assert (best_run / "steering_before.png").is_file()
    assert not (best_run / "steering_after.png").exists()
