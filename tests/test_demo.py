import json

import pytest

from clonedrive.cli import main


@pytest.mark.slow
def test_quick_demo_runs_every_stage_from_an_empty_folder(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--out", str(out), "--no-video"]) == 0
    summary = json.loads((out / "demo.json").read_text())
    assert list(summary["stages"]) == ["record", "train", "evaluate", "report"]
    assert summary["stages"]["record"]["rows"] == 300  # 20 s at 15 Hz
    assert (out / "data" / "middle" / "driving_log.csv").is_file()
    assert (out / "train" / "model.keras").is_file()
    report = json.loads((out / "eval" / "eval.json").read_text())
    (run,) = report["runs"]
    assert run["track"] == "lake" and run["speed_mph"] == 15.0
    assert run["elapsed_s"] > 0 and run["distance_m"] > 10
    assert (out / "eval" / run["map_png"]).is_file()
    html = (out / "report.html").read_text()
    assert "Closed-loop" in html or "closed-loop" in html
    assert (out / "report.md").is_file()
    assert "demo finished" in capsys.readouterr().out

    # Run again on the same folder: finished stages are reused, not redone.
    assert main(["demo", "--quick", "--out", str(out), "--no-video"]) == 0
    again = json.loads((out / "demo.json").read_text())
    assert again["stages"]["record"]["recordings"][0]["reused"] is True


def test_the_full_demo_plans_valid_stages():
    """The full demo is too long for the suite; its plan (every stage's config, validated in
    __post_init__) is built here, so a config rule cannot break it unnoticed."""
    from dataclasses import replace

    from clonedrive.demo import DemoConfig, _evaluation_groups, demo_plan

    recordings, train, evaluation = demo_plan(DemoConfig())
    assert len(recordings) == 8 and train.epochs == 8
    groups = _evaluation_groups(DemoConfig(), evaluation)
    assert [(g.tracks, g.speeds_mph, g.unseen) for g in groups] == [
        (("lake",), (15.0, 30.0), 0), (("mountain",), (15.0, 25.0), 0), ((), (20.0,), 10)]
    assert all(replace(g) == g for g in groups)
