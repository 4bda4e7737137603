"""A run folder records what produced it: a command started in a folder that holds an earlier
run with other settings starts afresh (evaluate, bench) or refuses, naming the settings that
differ (dagger, train --resume); it never leaves the old results marked complete beside its own
config, nor labels them with its settings."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from support.cli_process import SRC, refused, run_clonedrive

from clonedrive.base.config import config_to_dict, save_config, write_json_atomic
from clonedrive.model.train_config import TrainConfig
from clonedrive.pipelines.dagger.config import DaggerConfig
from clonedrive.pipelines.dagger.loop import check_rerun

#: Polling interval while waiting for a child process to reach a stage [s].
POLL_S = 0.05


def old_evaluation(folder: Path) -> None:
    """A finished evaluation of another model, on another track, as evaluate writes it."""
    folder.mkdir(parents=True)
    write_json_atomic(folder / "config.json", {"tracks": ["mountain"], "laps": 3})
    write_json_atomic(folder / "eval.json", {"model": "/old/model.keras", "complete": True,
                                             "runs": [{"track": "mountain"}]})


def test_an_interrupted_evaluate_leaves_no_old_results_marked_complete(
        tmp_path: Path, tiny_model_path: Path) -> None:
    out = tmp_path / "eval"
    old_evaluation(out)
    before = (out / "config.json").read_text()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(SRC), *sys.path]))
    child = subprocess.Popen(
        [sys.executable, "-m", "clonedrive.cli", "evaluate", str(tiny_model_path), "--track",
         "lake", "--laps", "1", "--workers", "1", "--no-scenery", "--out", str(out)],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    while (out / "config.json").read_text() == before and child.poll() is None:
        time.sleep(POLL_S)
    child.send_signal(signal.SIGTERM)  # as soon as this run's config is written
    child.communicate()
    config = json.loads((out / "config.json").read_text())
    report = json.loads((out / "eval.json").read_text())
    assert config["tracks"] == ["lake"]
    assert report["model"] == str(tiny_model_path)  # the new run's, never the old one's
    assert {run["track"] for run in report["runs"]} <= {"lake"}
    assert report["complete"] is False or len(report["runs"]) == 1


def dagger_base(folder: Path, model: Path) -> Path:
    """A training run folder as far as dagger reads it before it starts: model, config and
    recipe."""
    folder.mkdir()
    (folder / "model.keras").write_bytes(model.read_bytes())
    save_config(TrainConfig(), folder / "config.json")
    (folder / "recipe.toml").write_text('[[recording]]\npath = "data"\n', encoding="utf-8")
    return folder


def earlier_dagger(out: Path, base: Path, **settings) -> dict:
    """``out`` as a DAgger run with ``settings`` left it: config.json and one iteration."""
    saved = {**config_to_dict(DaggerConfig(**settings)), "base": str(base.resolve())}
    (out / "iter_01" / "data").mkdir(parents=True)
    (out / "iter_01" / "data" / "collect.json").write_text('{"labels": 45}', encoding="utf-8")
    write_json_atomic(out / "config.json", saved)
    return saved


def test_dagger_refuses_to_reuse_iterations_made_with_other_settings(
        tmp_path: Path, tiny_model_path: Path) -> None:
    base = dagger_base(tmp_path / "base", tiny_model_path)
    out = tmp_path / "dagger"
    saved = earlier_dagger(out, base, tracks=("lake",), beta=0.5)
    result = run_clonedrive("dagger", base, "--out", out, "--track", "mountain", "--beta", "0.8",
                            "--no-scenery")
    message = refused(result, "dagger", 1)
    assert "tracks ['lake'] -> ['mountain']" in message and "beta 0.5 -> 0.8" in message
    assert json.loads((out / "config.json").read_text()) == saved  # not relabelled
    assert (out / "iter_01" / "data" / "collect.json").read_text() == '{"labels": 45}'


def test_dagger_reruns_with_its_own_settings_or_more_iterations(tmp_path: Path) -> None:
    base = tmp_path / "base"
    out = tmp_path / "dagger"
    saved = earlier_dagger(out, base, tracks=("lake",), iterations=2)
    check_rerun(out, saved)
    check_rerun(out, {**saved, "iterations": 4, "workers": 3, "plain_noise": 0.0})
    with pytest.raises(ValueError, match=r"base '.*base' -> '.*other'"):
        check_rerun(out, {**saved, "base": str(tmp_path / "other")})
