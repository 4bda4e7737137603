"""Whole recipes: the built-in ones load, a copied and edited one works, bad ones are refused
naming the file and the key."""

from __future__ import annotations

from importlib import resources

import pytest

from clonedrive.network.driving_settings import DrivingSettings
from clonedrive.pipelines.demo import DemoConfig, demo_plan
from clonedrive.recipes.book import (
    BUILT_IN,
    DEFAULT_RECIPE,
    is_whole_recipe,
    load_recipe_file,
)
from clonedrive.recipes.training import stage_dirs, train_stages


def _text(name: str) -> str:
    return resources.files("clonedrive.recipes").joinpath(f"{name}.toml").read_text("utf-8")


@pytest.mark.parametrize("name", BUILT_IN)
def test_built_in_recipes_load_with_every_part(name):
    recipe = load_recipe_file(name)
    assert recipe.name == name and recipe.version >= 1
    assert recipe.recordings and recipe.evaluation
    config = recipe.train_config()
    assert config.model == "fast"
    assert recipe.notes()["recipe"] == {"name": name, "version": recipe.version}


def test_best_is_the_default_and_drives_without_the_curve_rule():
    best = load_recipe_file(DEFAULT_RECIPE)
    assert DEFAULT_RECIPE == "best" and DemoConfig().recipe == "best"
    assert best.train_config().speed_head
    assert best.driving.slow_in_curves is False
    _, _, groups = demo_plan(DemoConfig())
    speeds = {speed for group in groups for speed in group.speeds_mph}
    assert 30.0 in speeds
    assert [group.unseen_speed_mph for group in groups if group.unseen] == [30.0]


def test_writeup_is_todays_demo():
    recipe = load_recipe_file("writeup")
    assert recipe.driving == DrivingSettings(slow_in_curves=True)
    config = recipe.train_config()
    assert (config.epochs, config.learning_rate, config.batch_size, config.crop_top_px,
            config.speed_head, config.balance) == (8, 1e-3, 128, 80, False, True)
    names = [spec.name for spec in recipe.recordings]
    assert names == ["middle", "left", "right", "turns", "mountain", "mountain_reverse",
                     "mountain_turns", "hairpin"]
    specs = {spec.name: spec for spec in recipe.data_recipe("data").recordings}
    assert specs["left"].steering_offset == 0.25 and specs["right"].steering_offset == -0.25
    assert specs["left"].cameras == "center" and specs["middle"].cameras == "all"
    assert all(specs[name].steering_offset == 0.0 for name in ("middle", "turns", "hairpin"))
    assert all(spec.flip and spec.correction == 0.2 for spec in specs.values())


def test_a_copied_and_edited_recipe_is_used(tmp_path):
    text = _text("best").replace('name = "best"', 'name = "mine"').replace(
        "epochs = 3", "epochs = 2").replace("steering_hold = 0.004", "steering_hold = 0.008")
    path = tmp_path / "mine.toml"
    path.write_text(text, encoding="utf-8")
    assert is_whole_recipe(path)
    recipe = load_recipe_file(path)
    assert recipe.label() == "mine v8"  # the copy keeps best's version
    assert recipe.train_config().epochs == 2
    assert recipe.driving.steering_hold == 0.008
    _, (train, *_), _ = demo_plan(DemoConfig(recipe=str(path), epochs=3))
    assert train.epochs == 3  # the demo's option overrides the file


def test_data_recipes_are_not_whole_recipes(tmp_path):
    path = tmp_path / "data.toml"
    path.write_text('[[recording]]\npath = "x"\n', encoding="utf-8")
    assert not is_whole_recipe(path)
    assert not is_whole_recipe(tmp_path / "missing.toml")


def test_recordings_are_found_by_name_in_a_data_folder(tmp_path):
    recipe = load_recipe_file("writeup")
    data = recipe.data_recipe(tmp_path)
    assert [spec.path for spec in data.recordings][0] == tmp_path / "middle"
    assert data.recordings[1].steering_offset == 0.25
    with pytest.raises(ValueError, match="--data FOLDER"):
        recipe.data_recipe_without_data()


@pytest.mark.parametrize("name, edit, message", [
    ("best", ("[train]", "[train]\nwarp = 9"), "warp"),
    ("best", ("steering_hold = 0.004", "steering_hold = 2.0"), "steering_hold"),
    ("best", ('name = "best"', 'name = ""'), "needs a name"),
    ("best", ("version = 8", "version = 0"), "version"),
    ("best", ("laps = 3", "laps = 0"), "laps"),
    ("best", ('style = "center"', 'style = "center"\ncolour = "red"'), "colour"),
    ("best", ("correction = 0.054", "correction = 7"), "correction"),
    ("best", ("speeds_mph = [15, 30]", "speeds_mph = [15, 300]"), "evaluate"),
    ("best", ("[recipe]", "[recipes]"), "recipes"),
    ("best", ("[[recording]]", "[[recording]]\npath = 'x'"), "path and recording settings"),
    # [[finetune]] tables are checked one by one, naming the table
    ("best", ("epochs = 1             #", "warp = 2\nepochs = 1 #"),
     r"\[\[finetune\]\] #2: .*warp"),
    ("best", ("[[finetune]]\nepochs = 2", "[[finetune]]\nepochs = 0"),
     r"\[\[finetune\]\] #1: .*epochs"),
])
def test_bad_recipes_are_refused_naming_file_and_key(tmp_path, name, edit, message):
    path = tmp_path / "bad.toml"
    path.write_text(_text(name).replace(*edit, 1), encoding="utf-8")
    with pytest.raises(ValueError, match=message) as caught:
        load_recipe_file(path)
    assert "bad.toml" in str(caught.value)


def test_unknown_recipe_names_the_built_in_ones():
    with pytest.raises(FileNotFoundError, match="best, writeup"):
        load_recipe_file("bestest")


def test_not_toml_is_refused(tmp_path):
    path = tmp_path / "x.toml"
    path.write_text("[recipe\nname=", encoding="utf-8")
    with pytest.raises(ValueError, match="not valid TOML"):
        load_recipe_file(path)


def test_best_fine_tunes_in_two_consistency_stages():
    stages = train_stages(load_recipe_file("best"))
    assert [(stage.epochs, stage.learning_rate, stage.consistency) for stage in stages[1:]] == [
        (2, 0.0005, 60), (1, 0.0005, 60)]  # the last stage keeps the one before's settings


def test_a_finetune_that_is_not_a_table_is_refused(tmp_path):
    path = tmp_path / "bad.toml"
    text = _one_finetune_table(_text("best"))
    without = text[:text.index("[finetune]")] + text[text.index("[drive]"):]
    path.write_text('finetune = "x"\n' + without, encoding="utf-8")
    with pytest.raises(ValueError, match="must be a table"):
        load_recipe_file(path)


def test_each_stage_trains_in_its_own_folder(tmp_path):
    assert stage_dirs(tmp_path, 1) == [tmp_path]
    assert stage_dirs(tmp_path, 2) == [tmp_path / "base", tmp_path]
    assert stage_dirs(tmp_path, 4) == [tmp_path / "base", tmp_path / "stage2",
                                       tmp_path / "stage3", tmp_path]


def _one_finetune_table(text: str) -> str:
    """A recipe's text with its ``[[finetune]]`` tables replaced by one ``[finetune]`` table."""
    start, end = text.index("[[finetune]]"), text.index("[drive]")
    return (text[:start] + "[finetune]\nepochs = 2\nlearning_rate = 0.0005\nconsistency = 30\n\n"
            + text[end:])



def test_a_recipes_bench_names_the_splits_the_demo_benches(tmp_path):
    from clonedrive.bench.suite import SuiteError
    from clonedrive.pipelines.demo import bench_plan

    path = tmp_path / "benched.toml"
    path.write_text(_text("writeup") + '\n[bench]\nsplits = ["dev", "hard-30"]\n',
                    encoding="utf-8")
    recipe = load_recipe_file(path)
    assert recipe.bench.splits == ("dev", "hard-30") and recipe.bench.suite is None
    plan = bench_plan(DemoConfig(recipe=str(path), workers=1), recipe, tmp_path / "m.keras")
    assert plan.splits == ("dev", "hard-30") and plan.suite == "v4" and plan.workers == 1
    assert plan.models == (f"writeup={tmp_path / 'm.keras'}",)
    assert bench_plan(DemoConfig(recipe=str(path), quick=True), recipe, tmp_path) is None
    assert load_recipe_file("writeup").bench is None
    # A split the suite does not have is refused when the demo plans, before any work.
    path.write_text(_text("writeup") + '\n[bench]\nsuite = "v2"\nsplits = ["dev"]\n',
                    encoding="utf-8")
    with pytest.raises(SuiteError, match="dev"):
        bench_plan(DemoConfig(recipe=str(path)), load_recipe_file(path), tmp_path)


@pytest.mark.parametrize("table, message", [
    ('[bench]\nsplits = "dev"\n', "splits"),
    ("[bench]\nsplits = []\n", "splits"),
    ('[bench]\nsplits = ["dev"]\nsuite = 4\n', "suite"),
    ('[bench]\nsplits = ["dev"]\nworkers = 2\n', "workers"),
    ('bench = 3\n', r"\[bench\] must be a table"),
])
def test_a_bad_bench_table_is_refused_naming_the_file(tmp_path, table, message):
    path = tmp_path / "bad.toml"
    text = _text("writeup")
    text = table + text if not table.startswith("[") else text + "\n" + table
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ValueError, match=message) as caught:
        load_recipe_file(path)
    assert "bad.toml" in str(caught.value)


def test_an_oversized_recipe_is_refused_for_its_size_by_train(tmp_path, capsys):
    from clonedrive.cli import main
    from clonedrive.recipes.book import MAX_RECIPE_BYTES

    big = tmp_path / "big.toml"
    big.write_text('[recipe]\nname = "x"\nversion = 1\n# ' + "x" * MAX_RECIPE_BYTES + "\n",
                   encoding="utf-8")
    assert main(["train", "--recipe", str(big), "--out", str(tmp_path / "o")]) != 0
    err = capsys.readouterr().err
    assert f"{big}: {big.stat().st_size} bytes; a recipe file is at most" in err
    assert "unknown key" not in err and not (tmp_path / "o").exists()
