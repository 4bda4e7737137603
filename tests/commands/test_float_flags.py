"""Flags that cannot train or drive are refused before any work: NaN, infinity and values out
of range exit 2 with one line naming the setting, for train, dagger and the steering options
every driving verb shares (no run folder is left behind)."""

from __future__ import annotations

from pathlib import Path

import pytest
from support.cli_process import refused, run_clonedrive

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "udacity" / "stationary"


@pytest.mark.parametrize(("flag", "value", "named"), [
    ("--lr", "inf", "learning_rate must be in (0, 1], got inf"),
    ("--lr", "1e30", "learning_rate must be in (0, 1], got 1e+30"),
    ("--dropout", "nan", "dropout must be in [0, 1), got nan"),
    ("--block-s", "inf", "block_s must be a positive number of seconds, got inf"),
    ("--correction", "nan", "correction must be in [0, 1], got nan"),
    ("--val-fraction", "nan", "val_fraction"),
    ("--speed-loss-weight", "inf", "speed_loss_weight"),
    ("--shift-steering", "-0.001", "shift_steering_per_px must be in [0, 0.02], got -0.001"),
    ("--augment-looks", "nan", "augment_looks must be in [0, 1], got nan"),
    ("--augment-looks", "1.5", "augment_looks must be in [0, 1], got 1.5"),
    ("--looks-saturation", "nan", "looks_saturation must be in [0, 1], got nan"),
    ("--looks-saturation", "-0.5", "looks_saturation must be in [0, 1], got -0.5"),
])
def test_train_refuses_what_cannot_train(tmp_path: Path, flag: str, value: str,
                                         named: str) -> None:
    out = tmp_path / "run"
    result = run_clonedrive("train", FIXTURE, "--out", out, "--epochs", "1", flag, value)
    assert named in refused(result, "train", 2)
    assert not out.exists()


def test_a_resume_refuses_what_training_refuses(tmp_path: Path) -> None:
    out = tmp_path / "run"
    out.mkdir()
    result = run_clonedrive("train", FIXTURE, "--out", out, "--resume", "--dropout", "nan")
    assert "dropout must be in [0, 1)" in refused(result, "train", 2)


@pytest.mark.parametrize(("flag", "value", "named"), [
    ("--lr", "1e30", "learning_rate must be in (0, 1]"),
    ("--lr", "0", "learning_rate must be in (0, 1]"),
    ("--max-seconds", "inf", "max_seconds must be a positive number of seconds"),
    ("--beta", "nan", "beta must be in [0, 1]"),
])
def test_dagger_refuses_what_cannot_train(tmp_path: Path, flag: str, value: str,
                                          named: str) -> None:
    result = run_clonedrive("dagger", tmp_path / "base", "--out", tmp_path / "d", flag, value)
    assert named in refused(result, "dagger", 2)
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize(("flag", "value"), [("--steering-filter", "nan"),
                                             ("--steering-filter", "-1"),
                                             ("--steering-hold", "inf"),
                                             ("--speed-scale", "3"),
                                             ("--speed-scale", "nan"),
                                             ("--full-speed-at", "0.5"),
                                             ("--full-speed-at", "nan"),
                                             ("--steering-scale-from", "3"),
                                             ("--steering-scale-from", "nan"),
                                             ("--caution", "-1"), ("--caution", "inf"),
                                             ("--caution-from", "0.5"),
                                             ("--caution-from", "nan")])
def test_the_steering_options_are_refused_as_flags(tmp_path: Path, tiny_model_path: Path,
                                                   flag: str, value: str) -> None:
    result = run_clonedrive("evaluate", tiny_model_path, "--out", tmp_path / "e", flag, value)
    assert f"argument {flag}" in refused(result, "evaluate", 2)


def test_caution_without_mirror_averaging_is_one_line_naming_both(tmp_path: Path,
                                                                  tiny_model_path: Path) -> None:
    result = run_clonedrive("evaluate", tiny_model_path, "--out", tmp_path / "e",
                            "--caution", "40", "--no-mirror-average")
    assert "caution needs mirror averaging" in refused(result, "evaluate", 2)
