"""``clonedrive video FOLDER``: FOLDER.mp4 beside the folder, like Udacity's video.py."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from clonedrive.cli import main


def test_video_command(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    folder = tmp_path / "run1"
    folder.mkdir()
    for index in range(4):
        image = np.full((160, 320, 3), 40 * index, dtype=np.uint8)
        cv2.imwrite(str(folder / f"2026_01_01_00_00_00_{index:03d}.jpg"), image)
    assert main(["video", str(folder), "--fps", "30", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result == {"video": str(tmp_path / "run1.mp4"), "frames": 4, "fps": 30.0, "skipped": []}
    assert (tmp_path / "run1.mp4").stat().st_size > 0


def test_video_command_errors(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["video", str(tmp_path / "missing")]) == 1
    assert "missing" in capsys.readouterr().err
    assert main(["video", str(tmp_path), "--fps", "0"]) == 2
