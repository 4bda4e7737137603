"""A disk that fills while clonedrive writes: one line naming the path, exit 1, and no partial
file under a final name. The disk is real: a tmpfs of 1 MB mounted for the test (skipped
where mounting is not permitted)."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from support.measured import run_measured
from support.tiny_disk import fill, mounted_tmpfs

UDACITY = Path(__file__).resolve().parent / "fixtures" / "udacity" / "stationary"
#: What the tiny disk holds; smaller than the stationary recording's image cache (2.4 MB).
DISK_SIZE = "1m"
#: Left free for ``video``: less than its mp4 needs.
VIDEO_ROOM_BYTES = 8 << 10


@pytest.fixture()
def disk(tmp_path: Path) -> Iterator[Path]:
    with mounted_tmpfs(tmp_path / "disk", DISK_SIZE) as folder:
        yield folder


def last_line(text: str) -> str:
    return text.strip().splitlines()[-1]


def test_train_refuses_a_memmap_cache_the_disk_cannot_hold(disk: Path) -> None:
    """Mapping past a full disk dies of SIGBUS with no message: the space is checked first."""
    run = disk / "run"
    finished = run_measured("train", UDACITY, "--out", run, "--epochs", "1", "--cache",
                            "memmap", "--json")
    assert finished.rc == 1
    assert "Traceback" not in finished.stderr
    line = last_line(finished.stderr)
    assert line.startswith(f"clonedrive train: {run}/") and "image_cache" in line
    assert ": no space left on device for the image cache: it needs 2.5 MiB, " in line
    assert line.endswith(" MiB are free")
    free_mib = float(line.rsplit(", ", 1)[1].split(" ")[0])
    assert free_mib < 2.5  # what the small disk has left after the run's other files
    assert not list(run.rglob("*.keras"))


def test_video_on_a_full_disk_leaves_no_file_under_its_name(disk: Path) -> None:
    filler = fill(disk, VIDEO_ROOM_BYTES)
    out = disk / "frames.mp4"
    finished = run_measured("video", UDACITY / "IMG", "--out", out, "--json")
    assert finished.rc == 1
    assert "Traceback" not in finished.stderr
    assert last_line(finished.stderr) == (
        f"clonedrive video: {out}: no space left on the device (disk full)")
    assert sorted(disk.iterdir()) == [filler]


def test_evaluate_video_on_a_full_disk_leaves_no_mp4(disk: Path, tiny_model_path: Path) -> None:
    out = disk / "eval"
    finished = run_measured("evaluate", tiny_model_path, "--laps", "1", "--max-seconds", "20",
                            "--video", "--workers", "1", "--no-scenery", "--json",
                            "--out", out)
    assert finished.rc == 1
    assert "Traceback" not in finished.stderr
    assert last_line(finished.stderr) == (
        f"clonedrive evaluate: {out / 'lake_15mph.mp4'}: no space left on the device "
        "(disk full)")
    assert not [path for path in disk.rglob("*") if ".mp4" in path.name]


def test_the_tiny_disk_is_really_full(disk: Path) -> None:
    fill(disk, 0)
    with pytest.raises(OSError) as full:
        (disk / "more").write_bytes(bytes(64 << 10))
    assert full.value.errno == 28
    assert shutil.disk_usage(disk).free < 64 << 10


@pytest.mark.parametrize("verb", ["export", "ensemble"])
def test_model_writers_on_a_full_disk_name_the_path_and_leave_nothing(
        verb: str, disk: Path, tiny_model_path: Path) -> None:
    filler = fill(disk, 0)
    out = disk / ("model.onnx" if verb == "export" else "model.keras")
    argv = [tiny_model_path, "--onnx"] if verb == "export" else [tiny_model_path] * 2
    finished = run_measured(verb, *argv, "--out", out)
    assert finished.rc == 1
    assert "Traceback" not in finished.stderr
    line = last_line(finished.stderr)
    assert line.startswith(f"clonedrive {verb}: {disk}/")
    assert line.endswith(": no space left on the device (disk full)")
    assert sorted(disk.iterdir()) == [filler]


def test_record_on_a_full_disk_names_the_image_and_keeps_its_log_whole(disk: Path) -> None:
    fill(disk, 16 << 10)
    out = disk / "rec"
    finished = run_measured("record", "--track", "lake", "--no-scenery", "--laps", "1",
                            "--out", out)
    assert finished.rc == 1
    assert "Traceback" not in finished.stderr
    line = last_line(finished.stderr)
    assert line.startswith(f"clonedrive record: writing the log failed: {out / 'IMG'}/")
    assert line.endswith(".jpg: no space left on the device (disk full)")
    assert ".tmp" not in line and not list(out.rglob(".*.tmp.jpg"))
    rows = (out / "driving_log.csv").read_text(encoding="utf-8").splitlines()
    for row in [row for row in rows if not row.startswith("center,")]:
        for image in row.split(",")[:3]:
            assert (out / "IMG" / Path(image.strip()).name).is_file(), row
