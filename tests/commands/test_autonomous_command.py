"""``clonedrive autonomous``: our rendered car driven by a drive server over a real socket."""

from __future__ import annotations

import json
import math

import pytest

from clonedrive.cli import main
from clonedrive.drivers.policy import NetworkPolicy
from clonedrive.udacity.server import DriveServer


def test_drives_for_the_time_limit_and_prints_metrics(capsys: pytest.CaptureFixture,
                                                     tiny_model) -> None:
    policy = NetworkPolicy(tiny_model, set_speed_mph=9.0)
    with DriveServer(policy, port=0, status_interval_s=0) as server:
        code = main(["autonomous", "--track", "lake", "--json", "--max-seconds", "2",
                     "--no-scenery", "--port", str(server.port)])
        stats = server.stats()
    captured = capsys.readouterr()
    assert code == 0, captured.err
    summary = json.loads(captured.out)
    assert summary["steps"] == summary["server_replies"] == stats.steer == 30  # 2 s at 15 Hz
    assert summary["track"] == "lake" and summary["laps_target"] == 1
    for key in ("autonomy_pct", "mean_abs_cte_m", "max_abs_cte_m", "distance_m",
                "mean_speed_mph"):
        assert math.isfinite(summary[key]), key
    assert summary["distance_m"] > 0


def test_no_drive_server_is_a_clear_error(capsys: pytest.CaptureFixture, free_port: int) -> None:
    port = free_port
    code = main(["autonomous", "--json", "--no-scenery", "--max-seconds", "1",
                 "--port", str(port), "--connect-timeout", "0.3"])
    assert code == 1
    err = capsys.readouterr().err
    assert f"cannot connect to ws://127.0.0.1:{port}/socket.io/" in err
    assert "clonedrive drive" in err


def test_bad_arguments(capsys: pytest.CaptureFixture) -> None:
    assert main(["autonomous", "--track", "nowhere", "--json"]) == 2
    assert "nowhere" in capsys.readouterr().err
    assert main(["autonomous", "--laps", "0", "--json"]) == 2
    assert "laps" in capsys.readouterr().err
