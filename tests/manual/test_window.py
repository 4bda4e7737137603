"""The ``clonedrive sim`` shell, headless: the software renderer in an offscreen buffer, and the
command's behaviour without a display. (The on-screen OpenGL window needs a display; its input
path was checked by hand under Xvfb with xdotool.)"""

from __future__ import annotations

import json

import numpy as np

from clonedrive.base.images import read_rgb
from clonedrive.cli import main
from clonedrive.data.driving_log import read_driving_log
from clonedrive.manual.config import ManualConfig
from clonedrive.manual.session import DrivingSession
from clonedrive.manual.window import WINDOW_SIZE, run_window
from clonedrive.sim.simulator import SimConfig

WIDTH, HEIGHT = WINDOW_SIZE
VIEW_HEIGHT = WIDTH // 2


def test_a_scripted_offscreen_drive_records_and_draws_view_and_hud(tmp_path):
    session = DrivingSession(ManualConfig(scenery=False), tmp_path / "manual",
                             sim_config=SimConfig(scenery=False))
    shot = tmp_path / "shot.png"
    summary = run_window(session, onscreen=False, track="lake", hold=("w",), record=True,
                         steps=20, screenshot=shot)
    assert summary.steps == 20 and summary.rows_recorded == 20 and summary.track == "lake"
    assert summary.renderer.startswith("TinyPanda")
    log = read_driving_log(tmp_path / "manual", verify_images="decode")
    assert len(log.rows) == 20 and log.skipped == []
    assert session.sim is None  # the run closed the session's simulator

    image = read_rgb(shot)
    assert image.shape == (HEIGHT, WIDTH, 3)
    # The view is the last center image scaled up: sky blue at the top, road grey below.
    sky = image[10:60, 100:800].reshape(-1, 3).mean(axis=0)
    assert sky[2] > sky[0] + 30
    # The HUD panel is dark with bright text; the REC badge is red at the top right.
    panel = image[VIEW_HEIGHT + 2:, :]
    assert np.median(panel) < 40 and panel.max() > 200
    badge = image[10:45, WIDTH - 80:WIDTH - 10].reshape(-1, 3).astype(int)
    assert ((badge[:, 0] > 180) & (badge[:, 1] < 110)).sum() > 30


def test_offscreen_the_menu_is_drawn_once(tmp_path):
    session = DrivingSession(ManualConfig(scenery=False), tmp_path / "manual")
    shot = tmp_path / "menu.png"
    summary = run_window(session, onscreen=False, screenshot=shot)
    assert summary.steps == 0 and summary.track == ""
    image = read_rgb(shot)
    assert image.shape == (HEIGHT, WIDTH, 3)
    assert image[40:260, 40:400].max() > 200  # menu text
    red = image[:, WIDTH // 2:].reshape(-1, 3).astype(int)
    assert ((red[:, 0] > 200) & (red[:, 1] < 100)).sum() > 20  # the map's start marker


def test_the_command_without_a_display_says_so(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["sim"]) == 2
    assert "no display" in capsys.readouterr().err
    assert main(["sim", "--windowed"]) == 2


def test_the_command_renders_offscreen_and_records(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out, shot = tmp_path / "drive", tmp_path / "sim.png"
    code = main(["sim", "--track", "mountain", "--no-scenery", "--hold", "w,a", "--steps", "6",
                 "--record", "--out", str(out), "--screenshot", str(shot), "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["steps"] == 6 and summary["rows_recorded"] == 6
    assert summary["track"] == "mountain" and summary["onscreen"] is False
    assert summary["screenshot"] == str(shot) and shot.is_file()
    rows = read_driving_log(out, verify_images="exists").rows
    assert [round(row.steering, 2) for row in rows] == [-0.08, -0.16, -0.24, -0.32, -0.4, -0.48]


def test_the_command_names_a_bad_track(capsys):
    assert main(["sim", "--offscreen", "--track", "moon"]) == 2
    assert "moon" in capsys.readouterr().err
