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
    # domain randomisation is one more look, chosen the same way
    assert RecordConfig(look="randomized").randomized
    assert RecordConfig(look="randomized").conditions() is None
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


def test_randomize_is_the_randomized_look(tmp_path, capsys) -> None:
    """One way to set the look: ``--randomize`` is ``--look randomized``, not a second switch."""
    from clonedrive.cli import main

    common = ["record", "--track", "lake", "--seconds", "0.2", "--no-scenery", "--seed", "5",
              "--start-time", "2026-01-01T12:00:00"]
    assert main([*common, "--randomize", "--out", str(tmp_path / "flag")]) == 0
    assert main([*common, "--look", "randomized", "--out", str(tmp_path / "look")]) == 0
    assert main([*common, "--out", str(tmp_path / "plain")]) == 0
    first = {name: read_rgb(read_driving_log(tmp_path / name).rows[0].center)
             for name in ("flag", "look", "plain")}
    assert np.array_equal(first["flag"], first["look"])
    assert not np.array_equal(first["look"], first["plain"])
    with pytest.raises(SystemExit):
        main([*common, "--randomize", "--look", "udacity", "--out", str(tmp_path / "both")])
    assert "not allowed with argument" in capsys.readouterr().err
