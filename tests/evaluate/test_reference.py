"""The expert's reference is cached by the track's geometry, not its name."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import pytest

from clonedrive.evaluate.reference import expert_reference


def _write_lake(path: Path, scale: float) -> Path:
    data = json.loads((resources.files("clonedrive.world") / "tracks" / "lake.json").read_text())
    data["name"] = "edited"
    data["centerline"] = [[coordinate * scale if axis < 2 else coordinate
                           for axis, coordinate in enumerate(point)]
                          for point in data["centerline"]]
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


def test_an_edited_track_file_gets_a_fresh_expert_reference(tmp_path: Path) -> None:
    track = _write_lake(tmp_path / "edited.json", 1.0)
    first = expert_reference(str(track), 20.0, max_seconds=20.0)
    assert expert_reference(str(track), 20.0, max_seconds=20.0) == first  # cached, the same
    _write_lake(track, 0.8)  # the same name, a smaller track: the expert drives it differently
    edited = expert_reference(str(track), 20.0, max_seconds=20.0)
    assert edited["distance_m"] != pytest.approx(first["distance_m"], abs=1e-6) or \
        edited["max_abs_cte_m"] != first["max_abs_cte_m"]
    # A renamed copy of the same geometry drives as the original.
    copy = _write_lake(tmp_path / "copy.json", 0.8)
    assert expert_reference(str(copy), 20.0, max_seconds=20.0) == edited
