"""``clonedrive evaluate`` and ``clonedrive autonomous`` give the same figures for one model.

Evaluation drives in-process (raw frames, batched inference); autonomous mode drives our
simulator as the Udacity client of a real ``clonedrive drive`` process over a socket on
127.0.0.1 (JPEG frames, numbers as strings). Both go through the one episode runner, so laps,
interventions and stop reasons must agree exactly; the cross-track error may differ only by what
JPEG compression does to the network's input.

The model is :func:`~clonedrive.network.tiny_model.build_road_follower`, hand-weighted so that it
drives without training; the tracks are small stadiums written here: a wide one it laps cleanly
and a tight one whose bends it cannot take at the set speed (interventions).
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from clonedrive.cli import main
from clonedrive.network.tiny_model import build_road_follower

SET_SPEED = "15"
#: Allowed |evaluate - autonomous| differences. JPEG at quality 75 (what the Udacity protocol
#: sends) shifts this colour-based network's steering a little: measured 0.02-0.04 m on mean
#: |CTE| and 0.06 m on max |CTE| for these runs; a step out of lock-step or another intervention
#: rule moves the figures far more (and the laps, interventions and event positions with them).
MEAN_CTE_TOLERANCE_M = 0.1
MAX_CTE_TOLERANCE_M = 0.25
ELAPSED_TOLERANCE = 0.01  #: relative
EVENT_POSITION_TOLERANCE_M = 2.0  #: where each off-road event happened, along the track


def stadium(name: str, radius_m: float, straight_m: float, arc_points: int = 8) -> dict:
    """A track file: two straights joined by half circles, driven counter-clockwise."""
    half = straight_m / 2
    points = [(0.0, -radius_m), (half / 2, -radius_m)]
    points += [(half + radius_m * math.cos(a), radius_m * math.sin(a))
               for a in (-math.pi / 2 + math.pi * i / arc_points for i in range(arc_points + 1))]
    points += [(half / 2, radius_m), (-half / 2, radius_m)]
    points += [(-half + radius_m * math.cos(a), radius_m * math.sin(a))
               for a in (math.pi / 2 + math.pi * i / arc_points for i in range(arc_points + 1))]
    points.append((-half / 2, -radius_m))
    return {"name": name, "version": 1, "theme": "lake", "width_m": 8.0, "closed": True,
            "centerline": [[round(x, 3), round(y, 3), 0.0] for x, y in points]}


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("parity")
    model = folder / "follower.keras"
    build_road_follower().save(model)
    paths = {"model": model}
    for name, radius, straight in (("wide", 15.0, 30.0), ("tight", 7.0, 40.0)):
        path = folder / "tracks" / f"{name}.json"  # absolute paths, as a user gives them
        path.parent.mkdir(exist_ok=True)
        path.write_text(json.dumps(stadium(name, radius, straight)))
        paths[name] = path
    return paths


@pytest.fixture(scope="module")
def drive_server(files: dict[str, Path]):
    """``clonedrive drive MODEL --port 0 --speed 15`` in its own process; yields its port."""
    command = [sys.executable, "-m", "clonedrive", "drive", str(files["model"]), "--port", "0",
               "--speed", SET_SPEED, "--status-every", "0"]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True,
                               env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        port = None
        for line in process.stderr:
            found = re.search(r"listening on ws://127\.0\.0\.1:(\d+)/socket\.io/", line)
            if found:
                port = int(found[1])
                break
        assert port is not None, "the drive server never said where it listens"
        yield port
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.communicate()


def run_json(capsys: pytest.CaptureFixture, argv: list[str]) -> dict:
    code = main(argv)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out)


@pytest.mark.slow
def test_evaluate_and_autonomous_agree_on_laps_interventions_and_cte(
        files: dict[str, Path], drive_server: int, tmp_path: Path,
        capsys: pytest.CaptureFixture) -> None:
    tracks = [str(files["wide"]), str(files["tight"])]
    evaluation = run_json(capsys, [
        "evaluate", str(files["model"]), "--track", tracks[0], "--track", tracks[1],
        "--speed", SET_SPEED, "--laps", "1", "--no-scenery", "--out", str(tmp_path / "eval"),
        "--workers", "1", "--json"])  # in this process: no worker start-up to wait for
    assert evaluation["complete"]
    remotes = [run_json(capsys, ["autonomous", "--track", track, "--speed", SET_SPEED, "--laps",
                                 "1", "--no-scenery", "--port", str(drive_server), "--json"])
               for track in tracks]
    print(json.dumps({"evaluate": evaluation["runs"], "autonomous": remotes}))  # on failure
    for track, evaluated, remote in zip(tracks, evaluation["runs"], remotes, strict=True):
        assert remote["server_replies"] == remote["steps"]  # lock-step, one reply per step
        for key in ("track", "speed_mph", "laps_target", "laps_completed", "interventions",
                    "stopped", "timed_out"):
            assert remote[key] == evaluated[key], (track, key)
        assert remote["mean_abs_cte_m"] == pytest.approx(evaluated["mean_abs_cte_m"],
                                                         abs=MEAN_CTE_TOLERANCE_M), track
        assert remote["max_abs_cte_m"] == pytest.approx(evaluated["max_abs_cte_m"],
                                                        abs=MAX_CTE_TOLERANCE_M), track
        assert remote["elapsed_s"] == pytest.approx(evaluated["elapsed_s"],
                                                    rel=ELAPSED_TOLERANCE), track
        remote_events = [event["s_m"] for event in remote["off_road_events"]]
        evaluated_events = [event["s_m"] for event in evaluated["off_road_events"]]
        assert remote_events == pytest.approx(evaluated_events,
                                              abs=EVENT_POSITION_TOLERANCE_M), track
    wide, tight = evaluation["runs"]
    # The cases are what they claim: a clean lap, and a lap spoiled by interventions.
    assert (wide["laps_completed"], wide["interventions"], wide["stopped"]) == (1, 0, "laps")
    assert tight["laps_completed"] == 0 and tight["interventions"] >= 2
    assert tight["stopped"] == "laps"
