"""record --look udacity: a recording made in a look drawn from a condition family."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clonedrive.base.images import read_rgb
from clonedrive.data.driving_log import read_driving_log
from clonedrive.data.recorder import RecordConfig, record
from clonedrive.sim.conditions import FAMILIES, TRAINING_LOOKS


def test_looks_are_checked() -> None:
    assert "udacity" in TRAINING_LOOKS and "dusk" not in TRAINING_LOOKS
    with pytest.raises(ValueError, match="look 'dusk' is not one of"):
        RecordConfig(look="dusk")
    with pytest.raises(ValueError, match="choose one"):
        RecordConfig(look="udacity", randomize=True)
    # each seed draws its own look, the same one every time
    assert RecordConfig(look="udacity", seed=3).conditions() == FAMILIES["udacity"].sample(3)
    assert RecordConfig(look="udacity", seed=3).conditions() != RecordConfig(
        look="udacity", seed=4).conditions()


def test_a_recording_in_the_udacity_look(tmp_path) -> None:
    common = {"track": "lake", "seconds": 0.2, "scenery": False,
              "start_time": "2026-01-01T12:00:00"}
    record(RecordConfig(**common), tmp_path / "plain", progress=False)
    record(RecordConfig(**common, look="udacity", seed=1), tmp_path / "look", progress=False)
    plain, look = (read_driving_log(tmp_path / name).rows for name in ("plain", "look"))
    assert len(plain) == len(look) > 0
    difference = np.abs(read_rgb(plain[0].center).astype(int) - read_rgb(look[0].center))
    assert difference.mean() > 3.0  # another road shade, lines, light
    saved = json.loads((tmp_path / "look" / "config.json").read_text())
    assert json.dumps(saved).count('"udacity"') >= 1
