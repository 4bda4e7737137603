"""A run folder someone shares cannot make the report carry files from elsewhere: paths named by
eval.json that are absolute or lead out with ``..``, and run files that are symbolic links, are
not embedded, and the report's notes name each one."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from clonedrive.report.writeup import write_report

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"


def test_planted_paths_are_refused_and_named(tmp_path: Path) -> None:
    picture = sorted((FIXTURES / "stationary" / "IMG").glob("*.jpg"))[0]
    secret = tmp_path / "secret.png"
    shutil.copy(picture, secret)
    run = tmp_path / "run"
    (run / "eval").mkdir(parents=True)
    (run / "loss.png").symlink_to(secret)
    (run / "steering_before.png").symlink_to(secret)
    (run / "history.csv").write_text("epoch,loss,val_loss\n0,0.5,0.6\n1,0.4,0.5\n",
                                     encoding="utf-8")
    (run / "eval" / "inside.png").symlink_to(secret)
    runs = [{"track": "lake", "speed_mph": 20.0, "laps_completed": 0, "laps_target": 1,
             "interventions": 1, "map_png": "/etc/hostname", "video": "../../secret.png",
             "off_road_events": [{"lap": 0, "time_s": 1.0, "s_m": 5.0, "cte_m": 4.0,
                                  "frame_png": "inside.png"}]}]
    (run / "eval" / "eval.json").write_text(json.dumps({"runs": runs, "complete": True}),
                                            encoding="utf-8")
    out = tmp_path / "out"
    result = write_report(run, out)
    notes = "\n".join(result.notes)
    assert "Refused to embed `/etc/hostname`" in notes and "an absolute path" in notes
    assert "Refused to embed `../../secret.png`" in notes and "`..`" in notes
    for name in ("loss.png", "steering_before.png", "inside.png"):
        assert f"Refused to embed `{name}`" in notes
        assert "is a symbolic link" in notes
    secret_bytes = secret.read_bytes()
    hostname = Path("/etc/hostname").read_bytes() if Path("/etc/hostname").is_file() else None
    for path in out.rglob("*"):
        if path.is_file():
            assert path.read_bytes() not in (secret_bytes, hostname), path
