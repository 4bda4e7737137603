"""The leaderboard's baselines (benchmarks/leaderboard/baselines.toml): every row's commands
are ones clonedrive's own parser accepts, a row that trains on another row's recordings finds
them where that row's commands put them, and the centre-camera recipe is a valid recipe whose
recordings are recorded by ``best`` as well (so it can train on best's data folder)."""

from __future__ import annotations

import importlib.util
import json
import shlex
import sys
from pathlib import Path

import pytest

from clonedrive.cli import build_parser
from clonedrive.commands.model_options import steering_options
from clonedrive.network.driving_settings import with_defaults
from clonedrive.recipes.book import load_recipe_file

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def board():
    spec = importlib.util.spec_from_file_location("leaderboard", ROOT / "benchmarks" /
                                                  "leaderboard.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["leaderboard"] = module
    spec.loader.exec_module(module)
    return module


def test_every_rows_commands_parse_and_follow_the_rows_they_need(board, capsys) -> None:
    table, rows = board.load_rows()
    assert {"best", "writeup", "best-dagger", "center", "center-dagger", "center-plain",
            "center-dart", "pilotnet", "seed-network", "ensemble"} <= set(rows)
    parser = build_parser()
    for name, row in rows.items():
        steps = (board.row_steps(table, rows, name, 1, "runs/lb")
                 + board.bench_steps(table, row, 1, "runs/lb"))
        made = []
        for command in steps:
            words = shlex.split(command)
            assert words[0] == "clonedrive", command
            args = parser.parse_args(words[1:])  # exits (a test failure) on a bad option
            assert args is not None
            if "--data" in words:  # trains on recordings an earlier step made
                data = words[words.index("--data") + 1]
                assert any(data.startswith(out) for out in made), (name, data, made)
            made.append(board.made_by(command))
        model = board.fill(row["model"], row, 1, "runs/lb")
        assert any(model.startswith(out) for out in made), (name, model)
        assert steps[-1].startswith("clonedrive bench merge") and "--compact" in steps[-1]
    assert board.main(["commands", "center", "--seed", "2", "--runs", "x"]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0] == ("clonedrive demo --recipe benchmarks/leaderboard/best-v2.toml --seed 2 "
                          "--unseen 0 --no-video --out x/best-s2")
    assert '"row": "center"' in printed[-1] and '"ran": 0' in printed[-1]


def test_the_center_recipe_records_a_subset_of_best_through_the_center_camera() -> None:
    center = load_recipe_file(ROOT / "benchmarks" / "leaderboard" / "center.toml")
    best = {spec.name: spec for spec in load_recipe_file("best").recordings}
    assert center.name == "center" and center.train["speed_head"] is True
    for spec in center.recordings:
        twin = best[spec.name]
        assert (spec.track, spec.style, spec.laps, spec.speed_mph, spec.reverse) == (
            twin.track, twin.style, twin.laps, twin.speed_mph, twin.reverse)
    assert center.data_table["defaults"]["cameras"] == "center"
    assert "left" not in {spec.name for spec in center.recordings}


def test_an_ensembles_seeds_are_made_of_models_no_other_seed_uses(board) -> None:
    table, rows = board.load_rows()
    made = [{board.made_by(command) for command in board.row_steps(table, rows, "ensemble",
                                                                     seed, "r")}
            for seed in range(3)]
    assert {"r/best-s3", "r/best-s4", "r/best-s5", "r/ensemble-s1.keras"} == made[1]
    assert not made[0] & made[1] and not made[1] & made[2] and not made[0] & made[2]


@pytest.mark.parametrize("name", ["best", "best-dagger", "ensemble"])
def test_a_row_made_today_drives_as_the_boards_models_of_its_method(board, name) -> None:
    # The board's models of these methods were made by recipe best v1; the rows train new
    # seeds with v2 (benchmarks/leaderboard/best-v2.toml, trained as v1), whose low-pass the
    # row's bench options turn off, so a new seed merges as the same method.
    table, rows = board.load_rows()
    bench = next(step for step in board.bench_steps(table, rows[name], 4, "r")
                 if step.startswith("clonedrive bench ") and " merge " not in step)
    args = build_parser().parse_args(shlex.split(bench)[1:])
    demos = [shlex.split(step) for step in board.row_steps(table, rows, name, 4, "r")
             if step.startswith("clonedrive demo ")]
    made_by = {words[words.index("--recipe") + 1] for words in demos}
    assert made_by == {"benchmarks/leaderboard/best-v2.toml"}
    recipe = load_recipe_file(ROOT / made_by.pop())
    assert recipe.label() == "best v2"
    pinned = recipe.driving.options()
    driven = {**pinned, **steering_options(args)}
    boards = json.loads((ROOT / "docs" / "leaderboard" / "bench.json").read_text())["driving"]
    assert pinned != with_defaults(boards[name]) and driven == with_defaults(boards[name])
    # Today's default recipe trains and drives otherwise: its models are another method.
    assert load_recipe_file("best").version > recipe.version


def test_the_best_v7_row_trains_with_the_kept_v7_recipe_and_drives_as_the_board(board) -> None:
    table, rows = board.load_rows()
    demos = [shlex.split(step) for step in board.row_steps(table, rows, "best-v7", 1, "r")
             if step.startswith("clonedrive demo ")]
    made_by = {words[words.index("--recipe") + 1] for words in demos}
    assert made_by == {"benchmarks/leaderboard/best-v7.toml"}
    recipe = load_recipe_file(ROOT / made_by.pop())
    assert recipe.label() == "best v7"
    boards = json.loads((ROOT / "docs" / "leaderboard" / "bench.json").read_text())["driving"]
    assert recipe.driving.options() == with_defaults(boards["best-v7"])
    assert load_recipe_file("best").version == recipe.version + 1
