"""One writer per recording folder: live locks refuse, stale locks are taken over."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from clonedrive.data.recorder import RecordConfig, record
from clonedrive.data.recording_lock import LOCK_NAME, RecordingLock, RecordingLockedError

HOLD_LOCK = """
import sys, time
from clonedrive.data.recording_lock import RecordingLock
lock = RecordingLock(sys.argv[1]).acquire()
print("locked", flush=True)
time.sleep(60)
"""


def hold_in_subprocess(folder: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    child = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(folder)], env=env,
                             stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "locked"
    return child


def test_the_lock_file_names_its_holder_and_goes_away(tmp_path: Path) -> None:
    with RecordingLock(tmp_path) as lock:
        held = json.loads((tmp_path / LOCK_NAME).read_text())
        assert held["pid"] == os.getpid() and lock.stale is None
    assert not (tmp_path / LOCK_NAME).exists()


def test_a_second_writer_is_refused_with_the_first_ones_pid(tmp_path: Path) -> None:
    with RecordingLock(tmp_path):
        with pytest.raises(RecordingLockedError, match=f"another recorder \\(PID {os.getpid()}"):
            RecordingLock(tmp_path).acquire()
    RecordingLock(tmp_path).acquire().release()  # free again once the first let go


def test_another_process_holding_the_lock_refuses_and_its_death_frees_it(tmp_path: Path) -> None:
    child = hold_in_subprocess(tmp_path)
    try:
        with pytest.raises(RecordingLockedError, match=f"PID {child.pid}"):
            RecordingLock(tmp_path).acquire()
    finally:
        child.send_signal(signal.SIGKILL)  # killed: no chance to remove its lock file
        child.wait()
        child.stdout.close()
    assert json.loads((tmp_path / LOCK_NAME).read_text())["pid"] == child.pid  # left behind
    with RecordingLock(tmp_path) as lock:
        assert lock.stale is not None and lock.stale["pid"] == child.pid
        assert json.loads((tmp_path / LOCK_NAME).read_text())["pid"] == os.getpid()


def test_a_locked_folder_is_not_touched_by_a_second_recording(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with RecordingLock(out):
        with pytest.raises(RecordingLockedError, match="another recorder"):
            record(RecordConfig(track="lake", seconds=0.5, scenery=False), out, progress=False)
        assert sorted(path.name for path in out.iterdir()) == [LOCK_NAME]


def test_a_folder_made_only_for_the_lock_is_removed_again(tmp_path: Path) -> None:
    with RecordingLock(tmp_path / "new"):
        assert (tmp_path / "new").is_dir()
    assert not (tmp_path / "new").exists()
    (tmp_path / "kept").mkdir()
    RecordingLock(tmp_path / "kept").acquire().release()
    assert (tmp_path / "kept").is_dir()  # it was there before
