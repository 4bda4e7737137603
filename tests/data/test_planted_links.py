"""No writes through planted links: a symbolic link (or a FIFO) that someone left at the name of
an output is refused with one line naming it, or replaced, never written through; the file it
points to keeps its bytes and its modification time."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from support.cli_process import refused, run_clonedrive

from clonedrive.base.config import atomic_path, write_json_atomic, write_text_atomic
from clonedrive.base.output_files import RefusedOutputError, open_output, probe_writable

RECORD = ("record", "--track", "lake", "--seconds", "0.4", "--no-scenery",
          "--start-time", "2020-01-01T00:00:00")


def planted(folder: Path, name: str, target: Path) -> tuple[bytes, int]:
    """A link ``folder/name`` -> ``target`` (a file holding some bytes); what to compare."""
    target.write_bytes(b"someone else's file\n")
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).symlink_to(target)
    return target.read_bytes(), target.stat().st_mtime_ns


def unchanged(target: Path, before: tuple[bytes, int]) -> bool:
    return (target.read_bytes(), target.stat().st_mtime_ns) == before


@pytest.mark.parametrize("name", ["driving_log.csv", "target_speed.csv", "config.json",
                                  ".clonedrive-recording.lock"])
def test_record_refuses_a_link_at_an_output_name(tmp_path: Path, name: str) -> None:
    target = tmp_path / "elsewhere.txt"
    before = planted(tmp_path / "rec", name, target)
    message = refused(run_clonedrive(*RECORD, "--out", tmp_path / "rec"), "record", 1)
    assert name in message and "symbolic link" in message
    assert unchanged(target, before)
    assert not (tmp_path / "rec" / "IMG").exists()  # refused before anything was written


def test_record_refuses_a_link_at_the_image_folder(tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "rec").mkdir()
    (tmp_path / "rec" / "IMG").symlink_to(elsewhere, target_is_directory=True)
    message = refused(run_clonedrive(*RECORD, "--out", tmp_path / "rec"), "record", 1)
    assert "IMG" in message and "symbolic link" in message
    assert list(elsewhere.iterdir()) == []


def test_record_refuses_a_fifo_at_the_log_name(tmp_path: Path) -> None:
    (tmp_path / "rec").mkdir()
    os.mkfifo(tmp_path / "rec" / "driving_log.csv")
    message = refused(run_clonedrive(*RECORD, "--out", tmp_path / "rec"), "record", 1)
    assert "driving_log.csv" in message and "not a regular file" in message


def test_open_output_refuses_links_and_fifos(tmp_path: Path) -> None:
    target = tmp_path / "elsewhere.txt"
    before = planted(tmp_path, "out.txt", target)
    for mode in ("w", "a", "ab"):
        with pytest.raises(RefusedOutputError, match="out.txt: is a symbolic link|symbolic"):
            open_output(tmp_path / "out.txt", mode)
    os.mkfifo(tmp_path / "pipe")
    with pytest.raises(RefusedOutputError, match="not a regular file"):
        open_output(tmp_path / "pipe", "a")
    assert unchanged(target, before)
    with open_output(tmp_path / "new.txt", "a") as handle:
        handle.write("written\n")
    assert (tmp_path / "new.txt").read_text() == "written\n"


def test_atomic_writers_replace_a_link_at_the_final_or_temporary_name(tmp_path: Path) -> None:
    target = tmp_path / "elsewhere.txt"
    before = planted(tmp_path / "run", "eval.json", target)
    write_json_atomic(tmp_path / "run" / "eval.json", {"complete": True})
    assert not (tmp_path / "run" / "eval.json").is_symlink()
    assert unchanged(target, before)
    temporary = tmp_path / "run" / f".recipe.{os.getpid()}.tmp.toml"
    temporary.symlink_to(target)
    write_text_atomic(tmp_path / "run" / "recipe.toml", "name = 'x'\n")
    assert (tmp_path / "run" / "recipe.toml").read_text() == "name = 'x'\n"
    assert unchanged(target, before)
    (tmp_path / "run" / f".loss.{os.getpid()}.tmp.png").symlink_to(target)
    with atomic_path(tmp_path / "run" / "loss.png") as path:
        assert not path.exists()  # the planted link is gone before the writer opens the name
        path.write_bytes(b"png")
    assert unchanged(target, before)


def test_the_write_probe_removes_a_link_at_its_name(tmp_path: Path) -> None:
    target = tmp_path / "elsewhere.txt"
    before = planted(tmp_path / "out", ".probe", target)
    probe_writable(tmp_path / "out", ".probe")
    assert not (tmp_path / "out" / ".probe").exists()
    assert unchanged(target, before)


def test_a_link_at_a_writer_lock_is_refused_in_one_line(tmp_path: Path,
                                                        tiny_model_path: Path) -> None:
    target = tmp_path / "elsewhere.txt"
    before = planted(tmp_path / "eval", ".clonedrive-writer.lock", target)
    result = run_clonedrive("evaluate", tiny_model_path, "--track", "lake", "--laps", "1",
                            "--out", tmp_path / "eval")
    message = refused(result, "evaluate", 1)
    assert ".clonedrive-writer.lock" in message and "symbolic link" in message
    assert unchanged(target, before)
