"""Every count on the command line has a stated maximum (commands/counts.py), refused while the
command line is parsed: exit 2, argparse's message naming the option and the limit."""

from __future__ import annotations

import pytest
from support.measured import run_measured

from clonedrive.bench import MAX_BATCH as MAX_BENCH_BATCH
from clonedrive.cli import main
from clonedrive.commands import counts

HUGE = "1000000000"
#: (verb and its other arguments, the count option, its maximum)
OPTIONS = [
    (["train", "rec", "--out", "run"], "--epochs", counts.MAX_EPOCHS),
    (["train", "rec", "--out", "run"], "--batch-size", counts.MAX_BATCH_SIZE),
    (["train", "rec", "--out", "run"], "--early-stopping", counts.MAX_PATIENCE),
    (["train", "rec", "--out", "run"], "--workers", counts.MAX_TRAIN_WORKERS),
    (["train", "rec", "--out", "run"], "--crop-top", counts.MAX_CROP_TOP_PX),
    (["record", "--out", "rec"], "--laps", counts.MAX_LAPS),
    (["record", "--out", "rec"], "--max-off-road", counts.MAX_OFF_ROAD_EVENTS),
    (["dagger", "base", "--out", "d"], "--iterations", counts.MAX_ITERATIONS),
    (["dagger", "base", "--out", "d"], "--laps", counts.MAX_LAPS),
    (["dagger", "base", "--out", "d"], "--epochs", counts.MAX_EPOCHS),
    (["dagger", "base", "--out", "d"], "--eval-laps", counts.MAX_LAPS),
    (["dagger", "base", "--out", "d"], "--unseen", counts.MAX_UNSEEN),
    (["dagger", "base", "--out", "d"], "--workers", counts.MAX_WORKERS),
    (["autonomous"], "--laps", counts.MAX_LAPS),
    (["demo"], "--epochs", counts.MAX_EPOCHS),
    (["demo"], "--unseen", counts.MAX_UNSEEN),
    (["demo"], "--workers", counts.MAX_WORKERS),
    (["bench", "model.keras"], "--workers", counts.MAX_WORKERS),
    (["bench", "model.keras"], "--batch", MAX_BENCH_BATCH),
    (["saliency", "model.keras", "rec", "--out", "s"], "--frames-per-log", None),
    (["sim"], "--steps", counts.MAX_STEPS),
    (["drive", "model.keras"], "--max-connections", counts.MAX_CONNECTIONS),
    (["report", "run"], "--max-failures", counts.MAX_SHOWN),
    (["crosscheck", "model.keras", "rec"], "--smooth", counts.MAX_SHOWN),
    (["crosscheck", "model.keras", "rec"], "--max-rows", counts.MAX_ROWS),
]


@pytest.mark.parametrize(("argv", "option", "most"), OPTIONS,
                         ids=[f"{argv[0]} {option}" for argv, option, _ in OPTIONS])
def test_each_count_has_a_stated_maximum(argv: list[str], option: str, most: int | None,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    if most is None:  # saliency's lives with the frames it writes
        from clonedrive.model.saliency import MAX_FRAMES as most
    with pytest.raises(SystemExit) as exited:
        main([*argv, option, HUGE])
    assert exited.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last == (f"clonedrive {argv[0]}: error: argument {option}: must be at most "
                    f"{most:,}, got 1,000,000,000")


def test_the_maximum_itself_is_taken(capsys: pytest.CaptureFixture[str]) -> None:
    assert counts.count(counts.MAX_LAPS)(str(counts.MAX_LAPS)) == counts.MAX_LAPS


@pytest.mark.parametrize("fps", ["1e9", "nan", "inf"])
def test_video_frame_rates_have_a_maximum(fps: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["video", "frames", "--fps", fps])
    assert exited.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        f"clonedrive video: error: argument --fps: must be at most {counts.MAX_FPS:g}, got {fps}")


def test_a_real_train_process_refuses_a_billion_epochs_before_allocating(tmp_path) -> None:
    finished = run_measured("train", tmp_path, "--out", tmp_path / "run", "--epochs", HUGE)
    assert finished.rc == 2
    assert "Traceback" not in finished.stderr
    assert finished.stderr.strip().splitlines()[-1].startswith(
        "clonedrive train: error: argument --epochs: must be at most")
    assert not (tmp_path / "run").exists()


def test_a_recipe_is_held_to_the_same_training_maxima(tmp_path) -> None:
    """A recipe file sets training counts too: TrainConfig states the maxima."""
    from clonedrive.model.train_config import MAX_COUNTS, TrainConfig

    with pytest.raises(ValueError, match=f"epochs must be at most {MAX_COUNTS['epochs']:,}"):
        TrainConfig(epochs=int(HUGE))
    assert TrainConfig(epochs=MAX_COUNTS["epochs"]).epochs == MAX_COUNTS["epochs"]


def test_help_states_each_maximum(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"(at most {counts.MAX_EPOCHS:,})" in text
    assert f"(at most {counts.MAX_BATCH_SIZE:,})" in text
    with pytest.raises(SystemExit):
        main(["video", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"(at most {counts.MAX_FPS:g}) (default: 60.0)" in text
