"""The leaderboard's brief shipped in the package: the board's own figures, kept in step."""

from __future__ import annotations

import json
from pathlib import Path

from clonedrive.bench.board import board_brief, board_text, main, shipped_board

BOARD = Path(__file__).resolve().parents[2] / "docs" / "leaderboard" / "bench.json"


def test_the_shipped_brief_is_the_repositorys_board() -> None:
    """After ``bench merge`` changes docs/leaderboard, run
    ``python -m clonedrive.bench.board docs/leaderboard/bench.json``."""
    report = json.loads(BOARD.read_text(encoding="utf-8"))
    assert shipped_board() == json.loads(board_text(report))
    assert set(shipped_board()["methods"]) == set(report["methods"])


def test_the_brief_keeps_each_methods_mean_per_split() -> None:
    report = {"suite": {"id": "v9"}, "methods": {"m": {"scores": {
        "dev": {"success_pct": {"mean": 50.0, "std": 1.0, "n": 3},
                "driving_score": {"mean": 0.7, "n": 3}, "lap_time_ratio": {"mean": 1.1},
                "smoothness_ratio": {}},
        "overall": {"success_pct": {"mean": 60.0}}}}}}
    brief = board_brief(report)
    assert brief == {"suite": "v9", "methods": {"m": {"dev": {
        "success_pct": 50.0, "driving_score": 0.7, "lap_time_ratio": 1.1,
        "smoothness_ratio": None, "models": 3}}}}
    assert board_brief({}) == {"suite": None, "methods": {}}


def test_the_writer_needs_one_file(capsys) -> None:
    assert main([]) == 2
    assert "usage" in capsys.readouterr().err
