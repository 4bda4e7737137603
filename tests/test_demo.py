import json

import pytest

from clonedrive.cli import main


@pytest.mark.slow
def test_quick_demo_runs_every_stage_from_an_empty_folder(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--quick", "--no-video"]) == 0
    out = tmp_path / "runs" / "demo-quick"  # its own folder: the full demo's stays empty
    assert sorted(path.name for path in (tmp_path / "runs").iterdir()) == ["demo-quick"]
    summary = json.loads((out / "demo.json").read_text())
    assert list(summary["stages"]) == ["record", "train", "evaluate", "report"]
    assert summary["stages"]["record"]["rows"] == 300  # 20 s at 15 Hz
    assert (out / "data" / "middle" / "driving_log.csv").is_file()
    assert (out / "train" / "model.keras").is_file()
    report = json.loads((out / "eval" / "eval.json").read_text())
    (run,) = report["runs"]
    assert run["track"] == "lake" and run["speed_mph"] == 15.0
    assert run["elapsed_s"] > 0 and run["distance_m"] > 10
    assert (out / "eval" / run["map_png"]).is_file()
    html = (out / "report.html").read_text()
    assert "Closed-loop" in html or "closed-loop" in html
    assert (out / "report.md").is_file()
    printed = capsys.readouterr().out
    assert "demo finished" in printed
    # A quick check reads as one: no lap count (its evaluation stops before a lap), and no
    # comparison with a recipe's full figures.
    assert "quick check: the model drove" in printed and "all: 0/1 laps" not in printed
    report_md = (out / "report.md").read_text()
    assert "Quick check passed: every stage ran" in report_md
    assert "laps clean" not in report_md and "measured 20" not in report_md
    assert "(mean over runs)" not in report_md  # no ratios to the expert in its headline
    assert summary["recipe"]["name"] == "best"
    assert report["recipe"]["name"] == "best" and report["mirror_average"] is True
    assert not report["slow_in_curves"]
    assert (out / "recipe.toml").read_text().startswith("# clonedrive's best driver")

    # Run again on the same folder: finished stages are reused, not redone.
    assert main(["demo", "--quick", "--out", str(out), "--no-video"]) == 0
    again = json.loads((out / "demo.json").read_text())
    assert again["stages"]["record"]["recordings"][0]["reused"] is True


@pytest.mark.parametrize("recipe", ["best", "writeup"])
def test_the_full_demo_plans_valid_stages(recipe):
    """The full demo is too long for the suite; its plan (every stage's config, validated in
    __post_init__) is built here, so a config rule cannot break it unnoticed."""
    from dataclasses import replace

    from clonedrive.pipelines.demo import DemoConfig, demo_plan

    recordings, stages, groups = demo_plan(DemoConfig(recipe=recipe))
    train = stages[0]
    assert all(replace(g) == g for g in groups)
    if recipe == "writeup":  # today's demo, unchanged
        assert len(recordings) == 8 and train.epochs == 8 and not train.speed_head
        assert len(stages) == 1
        assert [(g.tracks, g.speeds_mph, g.unseen, g.laps) for g in groups] == [
            (("lake",), (15.0, 30.0), 0, 2), (("mountain",), (15.0, 25.0), 0, 1),
            ((), (20.0,), 10, 1)]
        return
    assert train.speed_head and train.crop_top_px == 60
    assert [(g.tracks, g.speeds_mph, g.unseen) for g in groups] == [
        (("lake", "mountain"), (15.0, 30.0), 0), ((), (30.0,), 10)]
    assert all(g.slow_in_curves is None for g in groups)  # the model's own: no curve rule


def test_demo_options_override_the_recipe():
    from clonedrive.pipelines.demo import DemoConfig, demo_plan

    _, (train, *_), groups = demo_plan(DemoConfig(epochs=2, unseen=3, model="seed",
                                                  video=False, seed=4))
    assert (train.epochs, train.model, train.seed) == (2, "seed", 4)
    assert [g.unseen for g in groups if g.unseen] == [3]
    assert not any(g.video for g in groups)


@pytest.mark.parametrize("recipe", ["writeup", "best"])
def test_unseen_zero_leaves_out_the_unseen_tracks_group(recipe):
    from clonedrive.pipelines.demo import DemoConfig, demo_plan

    _, _, groups = demo_plan(DemoConfig(recipe=recipe, unseen=0))
    assert groups and all(g.tracks and not g.unseen for g in groups)


def test_a_run_folder_of_another_recipe_is_refused_not_reused(tmp_path, capsys):
    """The demo reuses finished stages; a folder holding another recipe's stages must not pass
    for this recipe's."""
    from clonedrive.pipelines.demo import RECORDING_SPEC_FILE

    out = tmp_path / "demo"
    middle = out / "data" / "middle"
    middle.mkdir(parents=True)
    (middle / "driving_log.csv").write_text("")
    (middle / RECORDING_SPEC_FILE).write_text('{"name": "middle", "laps": 99}')
    assert main(["demo", "--out", str(out), "--no-video"]) == 1
    assert "recorded with other settings" in capsys.readouterr().err


def test_a_model_of_another_recipe_is_refused(tmp_path, tiny_model_path):
    import shutil

    from clonedrive.network.driving_settings import DrivingSettings, notes_for, write_notes
    from clonedrive.pipelines.demo import DemoFolderError, _check_same_recipe
    from clonedrive.recipes.book import load_recipe_file

    train_dir = tmp_path / "train"
    train_dir.mkdir()
    shutil.copy(tiny_model_path, train_dir / "model.keras")
    best = load_recipe_file("best")
    with pytest.raises(DemoFolderError, match="no recipe"):
        _check_same_recipe(train_dir, best)
    write_notes(train_dir / "model.keras",
                notes_for(DrivingSettings(slow_in_curves=True), {"name": "writeup", "version": 1}))
    with pytest.raises(DemoFolderError, match=f"writeup v1, not {best.label()}"):
        _check_same_recipe(train_dir, best)
    write_notes(train_dir / "model.keras", best.notes())
    _check_same_recipe(train_dir, best)  # its own recipe: reused


def test_a_recipe_recording_can_be_drawn_in_another_look(tmp_path):
    """``look = "udacity"`` in a recipe's recording reaches the recorder: the frames differ
    from the same recording's in the theme's look, and the folder's spec names the look (and
    a spec without one has no ``look`` key, as folders recorded before looks existed)."""
    from clonedrive.base.images import read_rgb
    from clonedrive.data.driving_log import read_driving_log
    from clonedrive.pipelines.demo import RECORDING_SPEC_FILE, _record_stage
    from clonedrive.recipes.book import RecordSpec

    plain = RecordSpec(name="plain", track="lake", style="center", laps=1, speed_mph=15,
                       seconds=0.5)
    looked = RecordSpec(name="looked", track="lake", style="center", laps=1, speed_mph=15,
                        seconds=0.5, look="udacity")
    _record_stage([plain, looked], tmp_path, seed=0, progress=False, workers=1)
    specs = {name: json.loads((tmp_path / name / RECORDING_SPEC_FILE).read_text())
             for name in ("plain", "looked")}
    assert "look" not in specs["plain"] and specs["looked"]["look"] == "udacity"
    first = {name: read_rgb(read_driving_log(tmp_path / name).rows[0].center).astype(int)
             for name in ("plain", "looked")}
    assert abs(first["plain"] - first["looked"]).mean() > 5.0


def test_a_recipe_look_must_be_a_training_look(tmp_path):
    from importlib import resources

    from clonedrive.recipes.book import load_recipe_file

    text = resources.files("clonedrive.recipes").joinpath("best.toml").read_text("utf-8")
    path = tmp_path / "looks.toml"
    path.write_text(text.replace('name = "middle"', 'name = "middle"\nlook = "udacity"', 1)
                    .replace('name = "left"', 'name = "left"\nlook = "mars"', 1))
    with pytest.raises(ValueError, match=r"looks.toml: .*look 'mars' is not one of"):
        load_recipe_file(path)
    path.write_text(text.replace('name = "middle"', 'name = "middle"\nlook = "udacity"', 1))
    assert load_recipe_file(path).recordings[0].look == "udacity"
