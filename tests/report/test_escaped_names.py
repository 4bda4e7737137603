"""Names are the user's text, escaped wherever written into TOML, JSON or Markdown: a recording
name holding a newline, a ``#``, a ``|`` or a tag neither breaks ``recipe.toml`` (read back the
same) nor restructures ``report.md`` or ``leaderboard.md``."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from support.cli_process import run_clonedrive

from clonedrive.base.config import save_config
from clonedrive.data.recipe import default_recipe_for, load_recipe, recipe_to_toml
from clonedrive.model.train_config import TrainConfig

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "udacity" / "stationary"
NASTY = 'a\n# injected | x <b> "q" \\ ]] \u00e9'


def test_a_recipe_with_a_nasty_recording_name_reads_back_the_same(tmp_path: Path) -> None:
    folder = tmp_path / NASTY
    shutil.copytree(FIXTURE, folder)
    recipe = default_recipe_for([folder])
    (tmp_path / "recipe.toml").write_text(recipe_to_toml(recipe), encoding="utf-8")
    again = load_recipe(tmp_path / "recipe.toml")
    assert [(spec.name, spec.path) for spec in again.recordings] == [(NASTY, folder)]


def test_the_report_keeps_a_nasty_recording_name_on_its_own_table_row(tmp_path: Path) -> None:
    folder = tmp_path / "data" / NASTY
    shutil.copytree(FIXTURE, folder)
    run = tmp_path / "run"
    run.mkdir()
    (run / "recipe.toml").write_text(recipe_to_toml(default_recipe_for([folder])),
                                     encoding="utf-8")
    (run / "history.csv").write_text("epoch,loss,val_loss\n0,0.5,0.6\n", encoding="utf-8")
    save_config(TrainConfig(), run / "config.json")
    result = run_clonedrive("report", run, "--out", tmp_path / "report")
    assert result.returncode == 0, result.stderr[-2000:]
    markdown = (tmp_path / "report" / "report.md").read_text(encoding="utf-8")
    assert "injected" in markdown
    lines = markdown.splitlines()
    assert not any(line.startswith("# injected") for line in lines)
    assert "<b>" not in markdown
    row = next(line for line in lines if "injected" in line and line.startswith("| a "))
    rule = next(line for line in lines[lines.index(row)::-1] if line.startswith("|---"))
    assert len(re.findall(r"(?<!\\)\|", row)) == rule.count("|")  # one row, as many cells


@pytest.mark.slow
def test_the_leaderboard_keeps_suite_text_literal(tmp_path: Path, tiny_model_path: Path) -> None:
    suite = tmp_path / "suite.toml"
    suite.write_text('id = "tiny | x"\ndescription = """one\n# injected\n| a | b |"""\n'
                     '[[split]]\nname = "a\\n- item"\ndescription = "<b>x</b>"\n'
                     'tracks = ["lake"]\nspeeds_mph = [20.0]\nconditions = ["clear"]\n'
                     'seed = 3\n[conditions.clear]\n', encoding="utf-8")
    result = run_clonedrive("bench", tiny_model_path, "--suite", suite, "--max-seconds", "1",
                            "--no-scenery", "--workers", "1", "--out", tmp_path / "bench")
    assert result.returncode == 0, result.stderr[-2000:]
    lines = (tmp_path / "bench" / "leaderboard.md").read_text(encoding="utf-8").splitlines()
    assert lines[0] == "# Benchmark: suite tiny \\| x"
    assert not any(line.startswith(("# injected", "- item", "| a |")) for line in lines)
    assert not any("<b>" in line for line in lines)
