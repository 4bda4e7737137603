"""The generated write-up on a real (tiny) run folder: an expert recording and a real Udacity
recording, a model trained on them for one epoch, a closed-loop evaluation with video."""

from __future__ import annotations

import base64
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from clonedrive.cli import main
from clonedrive.evaluate.video import read_stills, read_stills_in_order
from clonedrive.report.context import OPTIONAL_SECTION_TITLES
from clonedrive.report.writeup import SECTION_TITLES, write_report

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"
SUBSECTIONS = ("Camera views", "Augmentation", "Speed control", "Track maps",
               "Stills from the videos", "Failure analysis")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    from clonedrive.data.recorder import RecordConfig, record
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.evaluate.rollout import EvalConfig, evaluate
    from clonedrive.model.train import train
    from clonedrive.model.train_config import TrainConfig
    from clonedrive.network.tiny_model import build_tiny_model

    run = tmp_path_factory.mktemp("run")
    record(RecordConfig(track="lake", style="left", seconds=3.0, scenery=False,
                        start_time="2026-01-02T03:04:05"), run / "data" / "lake_left",
           progress=False)
    shutil.copytree(FIXTURES / "lake_posix_mixed_columns", run / "data" / "udacity_lake")
    train(TrainConfig(model="fast", epochs=1, batch_size=64, export_h5=False),
          [run / "data" / "lake_left", run / "data" / "udacity_lake"], run / "train",
          progress=False)
    # The tiny network cannot drive: within 6 s it leaves the road (failure analysis).
    evaluate(NetworkPolicy(build_tiny_model(0), set_speed_mph=20.0),
             EvalConfig(tracks=("lake",), speeds_mph=(20.0,), laps=1, scenery=False,
                        max_seconds=6.0, video=True), run / "eval", progress=False)
    (run / "dagger.json").write_text(json.dumps(DAGGER_JSON), encoding="utf-8")
    (run / "demo.json").write_text(json.dumps({
        "config": {"quick": False, "epochs": 1},
        "stages": {"record": {"seconds": 1.5, "rows": 115}, "train": {"seconds": 9.0}},
    }), encoding="utf-8")
    return run


#: What `clonedrive dagger` writes, cut down to one iteration and the plain-cloning row.
DAGGER_JSON = {
    "config": {"tracks": ["mountain"]},
    "iterations": [
        {"iteration": 0, "method": "base", "beta": None, "labels_total": 0,
         "eval": {"unseen": {"success_pct": 25.0, "interventions_per_km": 1.5}}},
        {"iteration": 1, "method": "dagger", "beta": 0.5, "labels_total": 900,
         "collect": {"takeovers_per_km": 2.0},
         "eval": {"unseen": {"success_pct": 75.0, "interventions_per_km": 0.25,
                             "lap_time_ratio": 1.04}}},
    ],
    "plain": {"method": "plain", "labels_total": 900, "epochs": 2,
              "eval": {"unseen": {"success_pct": 50.0, "interventions_per_km": 0.75}}},
}


@pytest.fixture(scope="module")
def report(run_dir: Path, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    result = write_report(run_dir, out)
    return result, out, result.markdown_path.read_text(encoding="utf-8")


def _section(markdown: str, title: str) -> str:
    """A top-level section's text, found by its title (the report numbers it: "## 6. ...")."""
    start = re.search(rf"^## \d+\. {re.escape(title)}\n", markdown, flags=re.M).start()
    following = markdown.find("\n## ", start + 1)
    return markdown[start: following if following > 0 else None]


def _has_section(markdown: str, title: str) -> bool:
    return re.search(rf"^## \d+\. {re.escape(title)}\n", markdown, flags=re.M) is not None


def _table_rows(text: str) -> list[list[str]]:
    """Cells of the first Markdown table in ``text`` (header and rule excluded)."""
    lines = [line for line in text.splitlines() if line.startswith("|")]
    return [[cell.strip().strip("*") for cell in line.strip("|").split(" | ")]
            for line in lines[2:]]


def test_beyond_sections_compare_with_the_expert_saliency_and_dagger(report) -> None:
    result, out, markdown = report
    expert = _section(markdown, SECTION_TITLES["expert"])
    assert "lap time" in expert and _table_rows(expert)[0][0].startswith("lake")
    assert (out / "report" / "saliency.png").is_file()
    rows = _table_rows(_section(markdown, OPTIONAL_SECTION_TITLES["dagger"]))
    assert [row[0] for row in rows] == ["0", "1", "plain cloning (2 epochs)"]
    assert rows[1][2:6] == ["900", "2.00", "75", "0.25"]


def test_markdown_has_every_section_and_no_skip_notes(report) -> None:
    result, _, markdown = report
    numbered = re.findall(r"^## (\d+)\. ", markdown, flags=re.M)
    assert numbered == [str(n) for n in range(1, len(numbered) + 1)]  # numbered in order
    for title in SECTION_TITLES.values():
        assert _has_section(markdown, title)
    for title in SUBSECTIONS:
        assert f"\n### {title}\n" in markdown
    assert result.notes == []
    assert "could not be generated" not in markdown


def test_data_table_joins_recorder_config_recipe_and_row_counts(report, run_dir) -> None:
    from clonedrive.data.driving_log import read_driving_log

    _, _, markdown = report
    rows = {row[0]: row for row in _table_rows(_section(markdown, SECTION_TITLES["data"]))}
    left = read_driving_log(run_dir / "data" / "lake_left")
    assert rows["lake_left"][1:4] == ["lake", "left", "forward"]
    assert rows["lake_left"][6] == f"{len(left.rows)} / {left.total_rows}"
    assert rows["lake_left"][7] == "center + left/right (±0.2)"
    assert rows["udacity_lake"][1] == "–"  # a Udacity recording has no recorder config
    assert rows["udacity_lake"][6] == "70 / 70"
    assert rows["total"][6] == f"{len(left.rows) + 70} / {left.total_rows + 70}"


def test_a_copied_run_folder_lists_each_recording_once(tmp_path: Path, run_dir) -> None:
    """The training recipe names the original folder's recordings; the copy's own ``data/``
    holds the same logs, so each recording is one row, with the recipe's settings."""
    copy = tmp_path / "copy"
    shutil.copytree(run_dir, copy)
    result = write_report(copy, tmp_path / "out")
    markdown = result.markdown_path.read_text(encoding="utf-8")
    rows = _table_rows(_section(markdown, SECTION_TITLES["data"]))
    assert [row[0] for row in rows] == ["lake_left", "udacity_lake", "total"]
    assert rows[0][7] == "center + left/right (±0.2)"
    # A recording edited in the copy is not the one the model was trained on: listed apart.
    log = copy / "data" / "lake_left" / "driving_log.csv"
    log.write_text(log.read_text(encoding="utf-8") + "\n", encoding="utf-8")
    result = write_report(copy, tmp_path / "out2")
    rows = _table_rows(_section(result.markdown_path.read_text(encoding="utf-8"),
                                SECTION_TITLES["data"]))
    assert [row[0] for row in rows] == ["lake_left", "udacity_lake", "lake_left", "total"]
    assert rows[2][7] == "not in training recipe"


def test_layer_table_lists_the_models_layers_and_parameters(report, run_dir) -> None:
    import keras

    _, _, markdown = report
    model = keras.saving.load_model(run_dir / "train" / "model.keras", safe_mode=True,
                                    compile=False)
    rows = _table_rows(_section(markdown, SECTION_TITLES["network"]))
    assert [row[0] for row in rows[:-1]] == [layer.name for layer in model.layers]
    assert [row[1] for row in rows[:-1]] == [type(layer).__name__ for layer in model.layers]
    assert [int(row[3].replace(",", "")) for row in rows[:-1]] == [
        layer.count_params() for layer in model.layers]
    assert rows[-1][0] == "total"
    assert int(rows[-1][3].replace(",", "")) == model.count_params()
    assert rows[0][2] == "160 × 320 × 3"


def test_training_section_names_the_split_and_its_caveat(report) -> None:
    _, _, markdown = report
    training = _section(markdown, SECTION_TITLES["training"])
    assert "**Split used: random**" in training
    assert "flatters the validation loss" in training
    assert ["loss", "mse on the steering label"] in _table_rows(training)
    epochs = [row for row in _table_rows(training) if row[0] == "1"]
    assert len(epochs) == 1 and epochs[0][-1] == "best"
    assert "report/loss.png" in training


def test_results_match_eval_json_and_show_each_failure(report, run_dir) -> None:
    _, out, markdown = report
    evaluation = json.loads((run_dir / "eval" / "eval.json").read_text())
    (run,) = evaluation["runs"]
    results = _section(markdown, SECTION_TITLES["results"])
    first = _table_rows(results)[0]
    assert first[0] == "lake" and first[2].startswith("0/1")
    assert first[3] == str(run["interventions"])
    assert first[4] == f"{run['autonomy_pct']:.1f}"
    events = run["off_road_events"]
    assert events, "the tiny network should leave the road within 6 s"
    failures = results[results.index("### Failure analysis"):]
    failure_rows = _table_rows(failures)
    assert len(failure_rows) == len(events)
    assert [row[6] for row in failure_rows] == [f"{e['cte_m']:+.2f}" for e in events]
    assert "report/failures.png" in failures
    assert "report/stills_lake_20mph.png" in results
    assert "report/map_lake_20mph_map.png" in results
    assert "steering was smoothed" not in results  # as drive.py: nothing between


def test_results_say_when_the_steering_was_filtered_or_held(tmp_path: Path, run_dir) -> None:
    folder = tmp_path / "smoothed"
    shutil.copytree(run_dir / "eval", folder / "eval")
    path = folder / "eval" / "eval.json"
    evaluation = json.loads(path.read_text(encoding="utf-8"))
    path.write_text(json.dumps({**evaluation, "steering_filter_s": 0.2, "steering_hold": 0.05,
                                "mirror_average": True, "steering_scale_from_mph": 24.0}),
                    encoding="utf-8")
    results = _section(write_report(folder).markdown_path.read_text(encoding="utf-8"),
                       SECTION_TITLES["results"])
    assert "**The steering was smoothed**" in results
    assert "0.2 s time constant" in results and "within 0.05 of the wheel" in results
    assert "averaged with the mirrored frame's" in results
    assert "multiplied above 24 mph by 24 mph over the car's speed" in results


def test_markdown_links_existing_pngs_and_html_embeds_them(report) -> None:
    result, out, markdown = report
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", markdown)
    assert links and all(link.startswith("report/") for link in links)
    for link in links:
        assert (out / link).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(out / link for link in links) == sorted(result.figures)
    assert sorted(p.name for p in (out / "report").iterdir()) == sorted(
        {Path(link).name for link in links})

    page = result.html_path.read_text(encoding="utf-8")
    sources = re.findall(r'\bsrc="([^"]*)"', page)
    assert len(sources) == len(links)
    for source in sources:
        prefix = "data:image/png;base64,"
        assert source.startswith(prefix)
        assert base64.b64decode(source[len(prefix):])[:4] == b"\x89PNG"
    assert not re.findall(r'\bhref="(?!#)', page)  # only in-page links
    assert "<table>" in page and "max-width: 100%" in page


def test_timings_from_demo_json(report) -> None:
    _, _, markdown = report
    rows = _table_rows(_section(markdown, SECTION_TITLES["timings"]))
    assert [row[:2] for row in rows] == [["record", "1.5"], ["train", "9.0"], ["total", "10.5"]]
    assert rows[0][4] == "rows 115"


def test_stills_are_spread_over_the_video(run_dir) -> None:
    stills = read_stills(run_dir / "eval" / "lake_20mph.mp4", 3)
    times = [time_s for time_s, _ in stills]
    assert len(stills) == 3 and times == sorted(times) and times[0] > 0
    assert all(frame.ndim == 3 and frame.shape[2] == 3 for _, frame in stills)
    # Seeking lands on the same frames as reading through the video.
    fps = 15.0
    in_order = read_stills_in_order(run_dir / "eval" / "lake_20mph.mp4",
                                     [round(time_s * fps) for time_s in times], fps)
    assert [t for t, _ in in_order] == pytest.approx(times)
    assert all(np.array_equal(a, b) for (_, a), (_, b) in zip(stills, in_order, strict=True))
    assert read_stills(run_dir / "eval" / "missing.mp4") == []


def test_missing_pieces_give_notes_not_crashes(tmp_path: Path, run_dir: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    result = write_report(empty)
    markdown = result.markdown_path.read_text(encoding="utf-8")
    # Nothing to show: every section is left out, and the introduction says which and why.
    assert "\n## " not in markdown
    assert len(result.notes) == len(SECTION_TITLES)
    left_out = markdown[markdown.index("**Not in this report**"):]
    for title in SECTION_TITLES.values():
        assert f"- {title}: " in left_out
    assert result.figures == [] and "src=" not in result.html_path.read_text()

    # Only an evaluation, with a broken video; a training folder with a corrupt model.
    partial = tmp_path / "partial"
    shutil.copytree(run_dir / "eval", partial / "eval")
    (partial / "eval" / "lake_20mph.mp4").write_bytes(b"not a video")
    (partial / "train").mkdir()
    (partial / "train" / "model.keras").write_bytes(b"not a model")
    result = write_report(partial)
    markdown = result.markdown_path.read_text(encoding="utf-8")
    network = _section(markdown, SECTION_TITLES["network"])
    assert "could not be generated" in network
    assert "`lake_20mph.mp4` is missing or unreadable" in markdown
    assert "report/failures.png" in markdown  # the rest of the results is there

    (partial / "eval" / "eval.json").write_text("{ not json", encoding="utf-8")
    result = write_report(partial)
    results = _section(result.markdown_path.read_text(), SECTION_TITLES["results"])
    assert "eval.json` is unreadable" in results


def test_report_command_writes_into_out(tmp_path: Path, run_dir: Path, capsys) -> None:
    (run_dir / "eval" / "eval.json").stat()  # the module's run folder is untouched
    partial = tmp_path / "run"
    shutil.copytree(run_dir / "train", partial)  # a training folder given as RUN_DIR
    out = tmp_path / "out"
    assert main(["report", str(partial), "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert Path(printed["markdown"]) == out / "report.md"
    assert Path(printed["html"]).is_file()
    assert any("eval.json" in note for note in printed["notes"])
    assert not (partial / "report.md").exists()
    assert main(["report", str(tmp_path / "nowhere")]) == 2


def test_the_summary_leads_with_clean_laps_calm_and_fast_and_names_the_recipe(
        tmp_path: Path, run_dir) -> None:
    folder = tmp_path / "recipe"
    shutil.copytree(run_dir / "eval", folder / "eval")
    path = folder / "eval" / "eval.json"
    evaluation = json.loads(path.read_text(encoding="utf-8"))
    path.write_text(json.dumps({**evaluation, "recipe": {"name": "best", "version": 1}}),
                    encoding="utf-8")
    markdown = write_report(folder).markdown_path.read_text(encoding="utf-8")
    summary = markdown.split("**In short:**", 1)[1].split("\n\n", 2)[1]
    first = summary.splitlines()[0]
    runs = evaluation["runs"]
    clean = sum(run["laps_completed"] for run in runs)
    assert first.startswith(f"- **{clean}/{sum(run['laps_target'] for run in runs)} laps clean**")
    interventions = sum(run["interventions"] for run in runs)
    assert f"({interventions} intervention{'' if interventions == 1 else 's'})" in first
    assert "mph" in first
    results = _section(markdown, SECTION_TITLES["results"])
    assert "recipe **best v1**" in results
    from clonedrive.recipes.book import load_recipe_file

    writeup = load_recipe_file("writeup")
    if writeup.measured:  # best compares itself with the write-up's stored figures
        assert f"beside the {writeup.label()} recipe" in results
        assert str(writeup.measured["steering_rate_ratio"]) in results


def test_a_recipe_name_cannot_inject_markup(tmp_path: Path, run_dir) -> None:
    folder = tmp_path / "hostile"
    shutil.copytree(run_dir / "eval", folder / "eval")
    path = folder / "eval" / "eval.json"
    evaluation = json.loads(path.read_text(encoding="utf-8"))
    path.write_text(json.dumps({**evaluation, "recipe": {"name": "<script>x</script>",
                                                         "version": 1}}), encoding="utf-8")
    html = write_report(folder).html_path.read_text(encoding="utf-8")
    assert "<script>x" not in html


def test_a_two_stage_run_shows_both_stages_epochs(tmp_path: Path, run_dir: Path) -> None:
    from clonedrive.model.train import train
    from clonedrive.model.train_config import TrainConfig

    run = tmp_path / "run"
    shutil.copytree(run_dir, run, ignore=shutil.ignore_patterns("train"))
    shutil.copytree(run_dir / "train", run / "train" / "base")  # the first stage
    # The second stage: one epoch from the first stage's model, as recipes.training runs it.
    train(TrainConfig(model="fast", epochs=1, batch_size=64, export_h5=False, consistency=5.0,
                      init_from=str(run / "train" / "base" / "model.keras")),
          [run / "data" / "lake_left", run / "data" / "udacity_lake"], run / "train",
          progress=False)
    result = write_report(run, tmp_path / "report")
    training = _section(result.markdown_path.read_text(encoding="utf-8"),
                        SECTION_TITLES["training"])
    epochs = [row for row in _table_rows(training) if row[0][:1].isdigit()]
    assert [row[0] for row in epochs] == ["1 (stage 1)", "2 (stage 2)"]
    settings = dict(row for row in _table_rows(training) if len(row) == 2)
    assert settings["epochs"] == "2 trained in 2 stages (1 + 1); the last stage's settings here"
    assert [row[-1] for row in epochs] == ["", "best"]  # model.keras is the fine-tune's
    assert "Training ran in 2 stages (the recipe's `[finetune]`)" in training
    markdown = result.markdown_path.read_text(encoding="utf-8")
    assert "1 epoch from scratch (`base/`), then a fine-tune of 1 epoch, best" in markdown
    assert "at epoch 2 (random split)" in markdown
    # Training's own loss.png holds the second stage only; the report plots both.
    plotted = tmp_path / "report" / "report" / "loss.png"
    assert plotted.is_file()
    assert plotted.read_bytes() != (run / "train" / "loss.png").read_bytes()
    # [[finetune]] tables: a stage between the first and the last trains in stage2/.
    shutil.copytree(run / "train" / "base", run / "train" / "stage2")
    result = write_report(run, tmp_path / "report3")
    markdown = result.markdown_path.read_text(encoding="utf-8")
    training = _section(markdown, SECTION_TITLES["training"])
    epochs = [row for row in _table_rows(training) if row[0][:1].isdigit()]
    assert [row[0] for row in epochs] == ["1 (stage 1)", "2 (stage 2)", "3 (stage 3)"]
    assert "Training ran in 3 stages" in training and "1 epoch(s) into `stage2/`" in training
    assert "1 epoch from scratch (`base/`), then 2 fine-tune stages of 1 + 1 epochs" in markdown


def test_a_run_without_balancing_shows_one_histogram(tmp_path: Path, run_dir: Path) -> None:
    run = tmp_path / "run"
    shutil.copytree(run_dir, run)
    dataset = json.loads((run / "train" / "dataset.json").read_text(encoding="utf-8"))
    dataset["balance"]["enabled"] = False
    (run / "train" / "dataset.json").write_text(json.dumps(dataset), encoding="utf-8")
    (run / "train" / "steering_after.png").unlink()
    markdown = write_report(run, tmp_path / "report").markdown_path.read_text(encoding="utf-8")
    balance = _section(markdown, SECTION_TITLES["balance"])
    assert "balancing **off**" in balance
    assert "(balancing off: every sample kept)" in balance
    assert "dashed line" not in balance and "steering_after" not in balance


def test_saliency_finds_a_frame_in_the_recordings_the_training_names(tmp_path: Path,
                                                                      run_dir: Path) -> None:
    """A run trained on recordings outside its folder (train data/middle --out runs/x) and
    not evaluated still gets an ordinary frame to look at."""
    run = tmp_path / "run"
    shutil.copytree(run_dir / "train", run / "train")
    markdown = write_report(run, tmp_path / "report").markdown_path.read_text(encoding="utf-8")
    saliency = _section(markdown, SECTION_TITLES["saliency"])
    assert "The run folder holds no evaluation; an ordinary frame (lake_left, row " in saliency
    assert "No frame to look at" not in markdown
