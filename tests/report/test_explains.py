"""The report explains itself: a sentence per ratio against the expert with its target, the
overlays ``clonedrive saliency`` wrote, the folders named as they are, empty sections left out."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from clonedrive.report.writeup import write_report

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"


def _eval_json(runs: list[dict]) -> dict:
    return {"runs": runs, "complete": True}


def _run(track: str, **ratios: float) -> dict:
    return {"track": track, "speed_mph": 30.0, "laps_completed": 1, "laps_target": 1,
            "interventions": 0, "expert": {"lap_time_s": 60.0, "steering_rate_per_s": 0.05},
            **ratios}


def test_each_ratio_gets_a_sentence_with_its_target(tmp_path: Path) -> None:
    run = tmp_path / "run"
    (run / "eval").mkdir(parents=True)
    runs = [_run("lake", lap_time_ratio=1.02, steering_rate_per_s_ratio=1.2,
                 lateral_jerk_mps3_ratio=1.4, steering_jerk_per_s2_ratio=9.0,
                 lateral_accel_rms_mps2_ratio=1.1),
            _run("mountain", lap_time_ratio=1.04, steering_rate_per_s_ratio=2.5,
                 lateral_jerk_mps3_ratio=1.3)]
    (run / "eval" / "eval.json").write_text(json.dumps(_eval_json(runs)), encoding="utf-8")
    markdown = write_report(run).markdown_path.read_text(encoding="utf-8")
    said = markdown[markdown.index("What the means say"):]
    assert "**lap time 1.03×**" in said
    assert "Target: at most 1.05× on average, no run above 1.05×; met" in said
    # A mean of 1.85 misses the 1.5 target, and one run above 2 is named.
    assert "**steering rate 1.85×**" in said
    assert "no run above 2×; missed (the largest run: 2.50×)" in said
    assert "**lat. jerk 1.35×**" in said and "at most 1.5× on average; met." in said
    assert "No target is set for it." in said  # steering jerk and lateral acceleration


def test_a_training_folder_as_run_folder_with_saliency_overlays(tmp_path: Path,
                                                                tiny_model_path: Path) -> None:
    """The README's step-by-step: ``train --out runs/x``, ``saliency ... --out runs/x/saliency``,
    ``report runs/x``. No recordings or evaluation inside the run folder."""
    from clonedrive.model.saliency import write_saliency

    run = tmp_path / "x"
    run.mkdir()
    shutil.copy(tiny_model_path, run / "model.keras")
    images = sorted((FIXTURES / "stationary" / "IMG").glob("center_*.jpg"))[:2]
    write_saliency(run / "model.keras", [str(path) for path in images], run / "saliency")
    result = write_report(run, tmp_path / "out")
    markdown = result.markdown_path.read_text(encoding="utf-8")
    assert "training: the run folder itself" in markdown and "training: `.`" not in markdown
    section = markdown[markdown.index(". Where the network looks\n"):]
    assert "`clonedrive saliency` wrote 2 overlay(s) into `saliency`" in section
    assert "report/saliency_written.png" in section
    assert (tmp_path / "out" / "report" / "saliency_written.png").is_file()
    # No demo.json: no "Run timings" heading, and the introduction says why it is left out.
    assert ". Run timings\n" not in markdown
    left_out = markdown[markdown.index("**Not in this report**"):markdown.index("**Contents**")]
    assert "- Run timings: No `demo.json`" in left_out


def test_overlays_named_outside_the_folder_are_not_shown(tmp_path: Path,
                                                         tiny_model_path: Path) -> None:
    run = tmp_path / "x"
    (run / "saliency").mkdir(parents=True)
    shutil.copy(tiny_model_path, run / "model.keras")
    outside = tmp_path / "secret.png"
    shutil.copy(sorted((FIXTURES / "stationary" / "IMG").glob("*.jpg"))[0], outside)
    (run / "saliency" / "link.png").symlink_to(outside)
    listing = {"frames": [{"source": "a", "overlay": str(outside)},
                          {"source": "b", "overlay": "../../secret.png"},
                          {"source": "c", "overlay": "link.png"}]}
    (run / "saliency" / "saliency.json").write_text(json.dumps(listing), encoding="utf-8")
    markdown = write_report(run, tmp_path / "out").markdown_path.read_text(encoding="utf-8")
    assert "saliency_written.png" not in markdown
    assert not (tmp_path / "out" / "report" / "saliency_written.png").exists()
