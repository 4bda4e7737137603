"""Fault injection: hostile names, hostile inputs, concurrent writers, full and read-only disks,
and hostile clients of the drive server.

Every probe checks the same three promises (issue 14): a clear one-line error and never a
traceback, nothing written outside ``--out``, and memory bounded whatever the input.
"""

from __future__ import annotations

import json
import math
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

from clonedrive.cli import main
from clonedrive.data.driving_log import read_driving_log

#: Address space a probe subprocess may use [bytes]: far below what an unbounded input takes.
PROBE_MEMORY_LIMIT = 1 << 30


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    """Run ``clonedrive ARGV`` in this process; (exit status, stdout, stderr)."""
    code = main([str(arg) for arg in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


_PROBE_SCRIPT = """
import contextlib, io, json, sys
from clonedrive.cli import main
from clonedrive.data.driving_log import read_driving_log
results = []
for argv in json.loads(sys.argv[1]):
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except BaseException as error:  # a probe that escapes the CLI is a failure to report
            import traceback
            traceback.print_exc(file=err)
            code = -1
    results.append([code, err.getvalue()])
print(json.dumps(results))
"""


def run_limited(*commands: list, timeout_s: float = 120.0) -> list[tuple[int, str]]:
    """Run each ``clonedrive ARGV`` of ``commands`` in one subprocess whose address space is
    capped at :data:`PROBE_MEMORY_LIMIT`; (exit status, stderr) per command."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (PROBE_MEMORY_LIMIT, PROBE_MEMORY_LIMIT))

    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    argvs = json.dumps([[str(arg) for arg in argv] for argv in commands])
    result = subprocess.run([sys.executable, "-c", _PROBE_SCRIPT, argvs], capture_output=True,
                            text=True, timeout=timeout_s, preexec_fn=limit, env=env)
    assert result.returncode == 0, result.stderr[-3000:]
    return [tuple(item) for item in json.loads(result.stdout.splitlines()[-1])]


def assert_one_clear_line(code: int, err: str) -> None:
    assert code != 0
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err


def files_under(folder: Path) -> set[Path]:
    return {path for path in folder.rglob("*") if path.is_file()}


def circle_track(name: str, radius_m: float = 60.0, count: int = 40) -> dict:
    angles = [2 * math.pi * i / count for i in range(count)]
    return {"name": name, "version": 1, "theme": "lake", "width_m": 8.0, "closed": True,
            "centerline": [[radius_m * math.cos(a), radius_m * math.sin(a), 0.0]
                           for a in angles]}


# --------------------------------------------------------------------------- hostile names

#: Track names that try to leave --out (the last repeats the first: it must not overwrite it).
HOSTILE_NAMES = ["../escaped", "/tmp/clonedrive-abs", "C:\\x/..\\nul\x00byte", "x" * 190,
                 "../escaped"]


def test_tracks_with_hostile_names_write_only_inside_out(tmp_path, capsys):
    sources = tmp_path / "sources"
    sources.mkdir()
    paths = []
    for index, name in enumerate(HOSTILE_NAMES):
        path = sources / f"t{index}.json"
        path.write_text(json.dumps(circle_track(name)))
        paths.append(path)
    out = tmp_path / "deep" / "out"
    escapes = [(out / f"{name}_map.png") for name in HOSTILE_NAMES if "\x00" not in name]
    existed = {path for path in escapes if os.path.lexists(path)}
    before = files_under(tmp_path)

    argv = ["tracks", "--out", out, "--no-strip"]
    for path in paths:
        argv += ["--track", path]
    code, printed, err = run_cli(capsys, *argv)

    assert code == 0, err
    written = files_under(tmp_path) - before
    assert written and all(out.resolve() in path.resolve().parents for path in written)
    assert len({path.name for path in written}) == len(HOSTILE_NAMES)  # no map overwrote another
    assert not [path for path in escapes if os.path.lexists(path) and path not in existed]


# --------------------------------------------------------------------------- hostile tracks

def hostile_track_files(folder: Path) -> dict[str, Path]:
    """name -> a track file (or folder) that must be refused with one line."""
    huge = circle_track("huge", radius_m=1e7)  # 2 KB: once 24 GB of allocations
    deep = b"[" * 100_000 + b"]" * 100_000
    files = {
        "huge_circle.json": json.dumps(huge).encode(),
        "utf16.json": json.dumps(circle_track("u")).encode("utf-16"),
        "digits.json": b'{"name": "d", "width_m": ' + b"7" * 5000 + b"}",
        "deep.json": deep,
        "version99.json": json.dumps({**circle_track("v"), "version": 99}).encode(),
        "jpeg.json": b"\xff\xd8\xff\xe0\x00\x10JFIF\x00\x01" + bytes(range(256)) * 8,
    }
    paths = {}
    for name, content in files.items():
        paths[name] = folder / name
        paths[name].write_bytes(content)
    paths["folder.json"] = folder / "folder.json"
    paths["folder.json"].mkdir()
    big = folder / "big.json"
    with open(big, "wb") as handle:
        handle.truncate(64 << 20)  # sparse 64 MiB
    paths["big.json"] = big
    return paths


def test_hostile_track_files_get_one_line_in_bounded_memory(tmp_path):
    paths = hostile_track_files(tmp_path)
    results = run_limited(*(["tracks", "--track", path, "--no-images"] for path in paths.values()))
    for path, (code, err) in zip(paths.values(), results, strict=True):
        assert_one_clear_line(code, err)
        assert str(path) in err


# --------------------------------------------------------------------------- two recorders

def test_a_second_recorder_into_the_same_folder_is_refused(tmp_path):
    out = tmp_path / "shared"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    argv = [sys.executable, "-m", "clonedrive.cli", "record", "--no-scenery", "--speed", "20",
            "--out", str(out), "--json"]
    # The first records for long enough that it surely holds the folder; it is interrupted
    # (Ctrl-C) once the second has been refused.
    first = subprocess.Popen([*argv, "--track", "lake", "--seconds", "3600"], env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lock = out / ".clonedrive-recording.lock"
        deadline = time.monotonic() + 120
        while not (out / "driving_log.csv").exists() and first.poll() is None \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        assert lock.exists(), "the first recorder never started writing"
        second = subprocess.run([*argv, "--track", "mountain", "--seconds", "2"], env=env,
                                capture_output=True, text=True, timeout=120)
    finally:
        first.send_signal(signal.SIGINT)
        printed, first_err = first.communicate(timeout=120)
    assert first.returncode == 130, first_err  # interrupted: every row written so far is whole
    assert_one_clear_line(second.returncode, second.stderr)
    assert "another recorder" in second.stderr and f"PID {first.pid}" in second.stderr
    rows = json.loads(printed)["rows"]
    log = read_driving_log(out, verify_images="exists")
    assert rows > 0 and len(log.rows) == log.total_rows == rows and not log.shared_images()
    assert len(list((out / "IMG").glob("*.jpg"))) == 3 * rows
    assert json.loads((out / "config.json").read_text())["track"] == "lake"
    assert not lock.exists()
