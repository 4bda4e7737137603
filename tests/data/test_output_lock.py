"""One writer per output, and no output over an input, for the verbs that write run folders and
model files: a second `clonedrive` process is refused with the first one's PID, a killed
writer's lock is taken over, and an output that is (or is inside) an input is refused before
anything is read."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from clonedrive.cli import main
from clonedrive.data.output_lock import (
    FILE_LOCK_SUFFIX,
    FOLDER_LOCK_NAME,
    check_output_over_inputs,
    claim_output,
)
from clonedrive.data.recording_lock import RecordingLockedError

HOLD = """
import sys, time
from clonedrive.data.output_lock import claim_output
lock = claim_output(sys.argv[1], sys.argv[2], is_file=sys.argv[3] == "file")
print("locked", flush=True)
time.sleep(120)
"""


def hold(verb: str, out: Path, *, is_file: bool = False) -> subprocess.Popen:
    """A real process holding ``out`` as ``clonedrive VERB`` would."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    child = subprocess.Popen(
        [sys.executable, "-c", HOLD, verb, str(out), "file" if is_file else "folder"],
        env=env, stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "locked"
    return child


def kill(child: subprocess.Popen) -> None:
    child.send_signal(signal.SIGKILL)  # no chance to remove its lock file
    child.wait()
    child.stdout.close()


def test_a_second_evaluate_into_one_folder_is_refused(tmp_path: Path, tiny_model_path: Path,
                                                      capsys) -> None:
    out = tmp_path / "eval"
    child = hold("evaluate", out)
    try:
        status = main(["evaluate", str(tiny_model_path), "--track", "lake", "--laps", "1",
                       "--out", str(out)])
    finally:
        kill(child)
    error = capsys.readouterr().err
    assert status == 1
    assert error.startswith(f"clonedrive evaluate: {out}: another clonedrive evaluate (PID "
                            f"{child.pid}")
    assert error.count("\n") == 1
    assert not (out / "eval.json").exists()


def test_a_killed_writers_lock_is_taken_over(tmp_path: Path) -> None:
    out = tmp_path / "run"
    child = hold("train", out)
    with pytest.raises(RecordingLockedError, match=f"clonedrive train \\(PID {child.pid}"):
        claim_output("train", out)
    kill(child)
    assert (out / FOLDER_LOCK_NAME).exists()  # left behind by the killed process
    with claim_output("train", out) as lock:
        assert lock.stale is not None and lock.stale["pid"] == child.pid
    assert not (out / FOLDER_LOCK_NAME).exists()


def test_a_model_file_output_is_held_beside_it(tmp_path: Path, tiny_model_path: Path,
                                               capsys) -> None:
    out = tmp_path / "ens.keras"
    child = hold("ensemble", out, is_file=True)
    try:
        assert (tmp_path / f".ens.keras{FILE_LOCK_SUFFIX}").exists()
        status = main(["ensemble", str(tiny_model_path), str(tiny_model_path), "--out",
                       str(out)])
        other = tmp_path / "other.keras"  # another file in the same folder is free
        with claim_output("ensemble", other, is_file=True):
            pass
    finally:
        kill(child)
    assert status == 1
    assert f"another clonedrive ensemble (PID {child.pid}" in capsys.readouterr().err
    assert not out.exists()


def test_ensemble_over_a_member_is_refused(tmp_path: Path, tiny_model_path: Path,
                                           capsys) -> None:
    member = tmp_path / "a.keras"
    member.write_bytes(tiny_model_path.read_bytes())
    before = member.read_bytes()
    status = main(["ensemble", str(member), str(tiny_model_path), "--out", str(member)])
    assert status == 1
    assert capsys.readouterr().err == (f"clonedrive ensemble: --out {member} is the input "
                                       f"{member}; write somewhere else\n")
    assert member.read_bytes() == before


def test_train_into_its_recording_is_refused(tmp_path: Path, capsys) -> None:
    recording = tmp_path / "rec"
    (recording / "IMG").mkdir(parents=True)
    (recording / "driving_log.csv").write_text("")
    for out, word in ((recording, "is the input"), (recording / "run", "is inside the input")):
        status = main(["train", str(recording), "--out", str(out), "--epochs", "1"])
        assert status == 1
        assert f"--out {out} {word} {recording}" in capsys.readouterr().err
    assert sorted(path.name for path in recording.iterdir()) == ["IMG", "driving_log.csv"]


def test_links_are_resolved_when_comparing(tmp_path: Path) -> None:
    real = tmp_path / "rec"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real)
    with pytest.raises(ValueError, match="is the input"):
        check_output_over_inputs(link, [real])
    check_output_over_inputs(tmp_path / "elsewhere", [real])  # no error
