"""Inputs that used to end in a traceback now end in one line, ``clonedrive VERB: ...``, naming
the value or file and the limit: a start time too late to name images after, a frame rate
ffmpeg cannot write, a suite with a table or a huge number where a value belongs, and TOML
nested deeper than Python's parser can follow."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from support.cli_process import refused, run_clonedrive

FIXTURE = Path(__file__).resolve().parent / "fixtures" / "udacity" / "stationary"
#: Nesting that exhausts Python's recursion limit in ~100 KB of text.
DEEP = 50_000
SUITE = """id = "tiny"
[[split]]
name = "a"
tracks = ["lake"]
speeds_mph = [20.0]
conditions = ["clear"]
seed = 3
[conditions.clear]
"""


def test_record_refuses_a_start_time_too_late_to_name_images(tmp_path: Path) -> None:
    result = run_clonedrive("record", "--track", "lake", "--seconds", "2", "--no-scenery",
                            "--out", tmp_path / "rec", "--start-time", "9999-12-31T23:59:59")
    assert "start_time 9999-12-31T23:59:59 is too late" in refused(result, "record", 2)
    assert not (tmp_path / "rec").exists()


def test_record_refuses_to_continue_a_log_named_for_the_year_9999(tmp_path: Path) -> None:
    folder = tmp_path / "rec"
    folder.mkdir()
    names = [f"IMG/{camera}_9999_06_01_00_00_00_000.jpg" for camera in ("center", "left",
                                                                         "right")]
    log = ",".join([*names, "0", "0", "0", "0"]) + "\n"
    (folder / "driving_log.csv").write_text(log, encoding="utf-8")
    result = run_clonedrive("record", "--track", "lake", "--seconds", "0.2", "--no-scenery",
                            "--out", folder)
    assert "too late to record after it" in refused(result, "record", 1)
    assert (folder / "driving_log.csv").read_text(encoding="utf-8") == log


@pytest.mark.parametrize(("fps", "message"), [
    ("1e30", "--fps: must be at most 1000, got 1e30"), ("nan", "--fps: must be at most 1000"),
    ("1e-6", "fps must be in [0.01, 1000]")])
def test_video_refuses_a_frame_rate_ffmpeg_cannot_write(tmp_path: Path, fps: str,
                                                        message: str) -> None:
    result = run_clonedrive("video", FIXTURE / "IMG", "--fps", fps, "--out", tmp_path / "v.mp4")
    assert message in refused(result, "video", 2)
    assert not (tmp_path / "v.mp4").exists()


@pytest.mark.parametrize(("change", "named"), [
    (("conditions = [\"clear\"]", "conditions = [{a = 1}]"), "conditions must be a list of"),
    (("seed = 3", "seed = 99999999999999999999999999"), "TOML integers are 64-bit"),
    (("speeds_mph = [20.0]", "speeds_mph = [" + "9" * 400 + "]"), "split[0].speeds_mph[0] is"),
    (("[conditions.clear]", "[conditions.clear]\nfog = [0, " + "9" * 400 + "]"),
     "conditions.clear.fog[1] is an integer of 400 digits"),
    (("seed = 3", "seed = " + "9" * 5000), "an integer with too many digits"),
    (("seed = 3", "seed = {a = 1}"), "seed must be a whole number"),
    (("[conditions.clear]", "[conditions.clear]\nline = []"), "non-empty list of colours"),
    (("[conditions.clear]", "[conditions.clear]\ndescription = {a = 1}"), "must be a string"),
    (("id = \"tiny\"", "id = \"tiny\"\ndescription = 5"), "description must be a string"),
])
def test_bench_refuses_a_table_or_huge_number_where_a_value_belongs(
        tmp_path: Path, tiny_model_path: Path, change: tuple[str, str], named: str) -> None:
    suite = tmp_path / "suite.toml"
    suite.write_text(SUITE.replace(*change), encoding="utf-8")
    result = run_clonedrive("bench", tiny_model_path, "--suite", suite, "--out", tmp_path / "b")
    assert named in refused(result, "bench", 2)


def test_train_refuses_a_recipe_with_a_huge_integer(tmp_path: Path) -> None:
    recipe = tmp_path / "data.toml"
    recipe.write_text(f'[[recording]]\npath = "{FIXTURE}"\ncorrection = {"9" * 400}\n',
                      encoding="utf-8")
    message = refused(run_clonedrive("train", "--recipe", recipe, "--out", tmp_path / "t"),
                      "train", 1)
    assert "recording[0].correction is an integer" in message


def nested(kind: str) -> str:
    """~100 KB of TOML nesting arrays or inline tables ``DEEP`` levels deep."""
    if kind == "arrays":
        return "x = " + "[" * DEEP + "]" * DEEP + "\n"
    return "x = " + "{a = " * (DEEP // 2) + "1" + "}" * (DEEP // 2) + "\n"


@pytest.mark.parametrize("kind", ["arrays", "tables"])
def test_a_deeply_nested_recipe_or_suite_is_refused_in_one_line(
        tmp_path: Path, tiny_model_path: Path, kind: str) -> None:
    path = tmp_path / "nested.toml"
    path.write_text(nested(kind), encoding="utf-8")
    for verb, argv, status in (("train", ("--recipe", path, "--out", tmp_path / "t"), 1),
                               ("demo", ("--recipe", path, "--out", tmp_path / "d"), 2),
                               ("bench", (tiny_model_path, "--suite", path, "--out",
                                          tmp_path / "b"), 2)):
        message = refused(run_clonedrive(verb, *argv), verb, status)
        assert "nested too deep to read" in message and str(path) in message


def test_a_run_folder_with_a_deeply_nested_recipe_is_refused_in_one_line(
        tmp_path: Path, tiny_model_path: Path) -> None:
    from clonedrive.base.config import save_config
    from clonedrive.model.train_config import TrainConfig

    run = tmp_path / "run"
    shutil.copytree(FIXTURE, tmp_path / "data")
    run.mkdir()
    (run / "recipe.toml").write_text(nested("arrays"), encoding="utf-8")
    (run / "model.keras").write_bytes(tiny_model_path.read_bytes())
    save_config(TrainConfig(), run / "config.json")
    message = refused(run_clonedrive("dagger", run, "--out", tmp_path / "d"), "dagger", 1)
    assert "nested too deep to read" in message
    assert not (tmp_path / "d").exists()
    (run / "state.json").write_text('{"epochs_done": 1}', encoding="utf-8")
    (run / "last.keras").write_bytes(tiny_model_path.read_bytes())
    message = refused(run_clonedrive("train", "--out", run, "--resume", "--epochs", "2"),
                      "train", 1)
    assert "nested too deep to read" in message


def test_bench_and_dagger_name_a_misspelt_split_before_driving_anything(
        tmp_path: Path, tiny_model_path: Path) -> None:
    suite = tmp_path / "suite.toml"
    suite.write_text(SUITE, encoding="utf-8")
    result = run_clonedrive("bench", tiny_model_path, "--suite", suite, "--split", "a",
                            "--split", "b", "--out", tmp_path / "b")
    assert "suite tiny: no split named b; it has a" in refused(result, "bench", 2)
    assert not (tmp_path / "b" / "bench.json").exists()
    result = run_clonedrive("dagger", tmp_path / "no-run", "--suite", suite, "--bench-split",
                            "dev", "--out", tmp_path / "d")
    assert "no split named dev" in refused(result, "dagger", 2)
