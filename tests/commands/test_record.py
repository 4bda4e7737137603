"""``clonedrive record``: arguments, the JSON summary, the human summary, errors."""

import json

from clonedrive.cli import main
from clonedrive.data.driving_log import read_driving_log

FAST = ["--track", "lake", "--seconds", "1", "--no-scenery", "--start-time",
        "2026-11-21T10:11:12"]


def test_json_summary_has_rows_and_off_road_events(tmp_path, capsys):
    out = tmp_path / "middle"
    code = main(["record", *FAST, "--style", "center", "--laps", "3", "--speed", "15",
                 "--out", str(out), "--noise", "0.1", "--seed", "2", "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["rows"] == 15 and summary["off_road_events"] == 0
    assert summary["stopped"] == "seconds"
    log = read_driving_log(out, verify_images="decode")
    assert len(log.rows) == 15 and not log.skipped
    config = json.loads((out / "config.json").read_text())
    assert (config["noise"], config["seed"], config["laps"]) == (0.1, 2, 3)


def test_human_summary_shows_rows_histogram_and_rate(tmp_path, capsys):
    code = main(["record", *FAST, "--out", str(tmp_path), "--reverse", "--header",
                 "--relative-paths", "--style", "left"])
    assert code == 0
    text = capsys.readouterr().out
    assert "rows: 15 written" in text
    assert "steering histogram" in text and "[-1.00, -0.82)" in text
    assert "samples/s" in text
    first = (tmp_path / "driving_log.csv").read_text().splitlines()[1]
    assert first.startswith("IMG/center_2026_11_21_10_11_12_000.jpg,")
    assert json.loads((tmp_path / "config.json").read_text())["reverse"] is True


def test_bad_arguments_get_a_clear_error(tmp_path, capsys):
    assert main(["record", "--out", str(tmp_path), "--speed", "45"]) == 2
    assert "--speed must be a speed in (0, 30] mph" in capsys.readouterr().err
    assert main(["record", "--out", str(tmp_path), "--track", "nowhere"]) == 2
    assert "unknown track 'nowhere'" in capsys.readouterr().err
    assert not (tmp_path / "driving_log.csv").exists()
