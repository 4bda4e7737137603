"""SIGTERM is handled as Ctrl-C is, by real `clonedrive` processes: the command stops with
status 143 and one line, its worker processes stop with it, and a killed worker's parent
leaves no worker behind."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

WAIT_S = 180.0  # the longest a test waits for a process to get somewhere (not a timing)


def spawned_workers(parent: int) -> set[int]:
    """The multiprocessing workers (spawned interpreters) whose parent is ``parent``."""
    workers = set()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            status = (entry / "status").read_text()
            command = (entry / "cmdline").read_bytes()
        except OSError:  # gone meanwhile
            continue
        ppid = next(line.split()[1] for line in status.splitlines()
                    if line.startswith("PPid:"))
        if int(ppid) == parent and b"spawn_main" in command:
            workers.add(int(entry.name))
    return workers


@contextmanager
def started(command: list[str], env: dict):
    """A clonedrive process (stderr captured), killed on the way out if still running."""
    process = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
    try:
        yield process
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def terminate(process: subprocess.Popen) -> str:
    """Send SIGTERM and wait for the process to end; its stderr."""
    process.send_signal(signal.SIGTERM)
    return process.communicate(timeout=WAIT_S)[1]


def wait_for(condition) -> bool:
    end = time.monotonic() + WAIT_S
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.1)
    return False


def alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "status").read_text()
    except OSError:
        return False
    return "State:\tZ" not in state  # a zombie has stopped


def test_sigterm_stops_evaluate_and_its_workers(tmp_path: Path, tiny_model_path: Path) -> None:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    command = [sys.executable, "-m", "clonedrive.cli", "evaluate", str(tiny_model_path),
               "--track", "lake", "--unseen", "4", "--laps", "20", "--unseen-laps", "20",
               "--workers", "2", "--batch", "1", "--no-scenery", "--out", str(tmp_path / "eval")]
    with started(command, env) as process:
        assert wait_for(lambda: spawned_workers(process.pid) or process.poll() is not None)
        workers = spawned_workers(process.pid)
        assert workers, "evaluate started no worker"
        err = terminate(process)
    assert process.returncode == 128 + signal.SIGTERM, err
    assert err.strip().splitlines()[-1] == "terminated"
    assert "Traceback" not in err
    assert wait_for(lambda: not any(alive(pid) for pid in workers))
    # evaluate writes a fresh eval.json (no runs, not complete) before it drives anything
    report = json.loads((tmp_path / "eval" / "eval.json").read_text(encoding="utf-8"))
    assert report["complete"] is False


def test_workers_stop_when_their_parent_is_killed(tmp_path: Path) -> None:
    """SIGKILL cannot be handled: each worker notices its parent is gone and stops."""
    script = (
        "import time\n"
        "from clonedrive.base.workers import run_tasks\n"
        "run_tasks(time.sleep, [600, 600], workers=2)\n"
    )
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    process = subprocess.Popen([sys.executable, "-c", script], env=env)
    try:
        assert wait_for(lambda: len(spawned_workers(process.pid)) == 2)
        workers = spawned_workers(process.pid)
    finally:
        process.kill()
        process.wait()
    assert wait_for(lambda: not any(alive(pid) for pid in workers))


def test_a_terminated_train_removes_its_image_cache(tmp_path: Path) -> None:
    recording = Path(__file__).resolve().parent / "fixtures" / "udacity" / "stationary"
    out = tmp_path / "run"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    command = [sys.executable, "-m", "clonedrive.cli", "train", str(recording), "--out",
               str(out), "--cache", "memmap", "--model", "fast", "--epochs", "10000",
               "--val-fraction", "0.3", "--json"]
    cache = out / "base" / "image_cache.u8"  # recipe best trains its first stage in base/
    with started(command, env) as process:
        assert wait_for(lambda: cache.exists() or process.poll() is not None)
        assert cache.exists(), process.communicate()[1]
        err = terminate(process)
    assert process.returncode == 128 + signal.SIGTERM, err
    assert not cache.exists()


_LARGE_TASKS = """
import sys
from clonedrive.base.interrupts import Terminated, interruptible
from clonedrive.base.workers import run_tasks
import holding
try:
    with interruptible():
        run_tasks(holding.hold, [bytes(4 << 20)] * 8, workers=2)  # each far above a pipe's 64 KB
except Terminated:
    sys.exit(143)
"""


def test_sigterm_while_large_tasks_wait_for_workers(tmp_path: Path) -> None:
    """Tasks much larger than a pipe's buffer, more than the workers take: SIGTERM still
    stops everything at once, and the tasks' temporary files go with it."""
    started_folder = tmp_path / "started"
    started_folder.mkdir()
    (tmp_path / "holding.py").write_text(
        "import os, time\n\ndef hold(payload):\n"
        f"    open(os.path.join({str(started_folder)!r}, str(os.getpid())), 'w').close()\n"
        "    time.sleep(600)\n")
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    env = dict(os.environ, TMPDIR=str(temporary),
               PYTHONPATH=os.pathsep.join([str(tmp_path), *sys.path]))
    with started([sys.executable, "-c", _LARGE_TASKS], env) as process:
        # Both workers hold a task: the other six wait to be sent.
        assert wait_for(lambda: len(list(started_folder.iterdir())) == 2)
        workers = spawned_workers(process.pid)
        err = terminate(process)
    assert process.returncode == 143, err
    assert "Traceback" not in err
    assert wait_for(lambda: not any(alive(pid) for pid in workers))
    assert list(temporary.iterdir()) == []
