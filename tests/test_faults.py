"""Fault injection: hostile names, hostile inputs, concurrent writers, full and read-only disks,
and hostile clients of the drive server.

Every probe checks the same three promises (issue 14): a clear one-line error and never a
traceback, nothing written outside ``--out``, and memory bounded whatever the input.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import re
import resource
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from clonedrive.cli import main
from clonedrive.data.driving_log import read_driving_log
from clonedrive.udacity import protocol
from clonedrive.udacity.server_config import IDLE_CLOSE_CODE

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
from clonedrive.udacity import protocol
from clonedrive.udacity.server_config import IDLE_CLOSE_CODE
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


def run_limited(*commands: list, memory_limit: int | None = PROBE_MEMORY_LIMIT,
                file_size_limit: int | None = None, timeout_s: float = 300.0
                ) -> list[tuple[int, str]]:
    """Run each ``clonedrive ARGV`` of ``commands`` in one subprocess whose address space is
    capped at ``memory_limit`` bytes and whose files may not grow past ``file_size_limit``
    (writes beyond fail with EFBIG); (exit status, stderr) per command."""

    def limit() -> None:
        if memory_limit is not None:
            resource.setrlimit(resource.RLIMIT_AS, (memory_limit, memory_limit))
        if file_size_limit is not None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a failed write, not a killed process
            resource.setrlimit(resource.RLIMIT_FSIZE, (file_size_limit, file_size_limit))

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


# --------------------------------------------------------------------------- full and read-only

def mount_tmpfs(folder: Path, options: str) -> bool:
    """Mount a tmpfs on ``folder`` if this process may (root, ``mount`` present)."""
    folder.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    result = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)],
                            capture_output=True)
    return result.returncode == 0


def unmount(folder: Path) -> None:
    subprocess.run(["umount", str(folder)], check=True, capture_output=True)


@pytest.fixture()
def full_disk(tmp_path):
    """(folder, small_disk): a 192 KiB tmpfs where it can be mounted; else a plain folder, and
    the probes run in a subprocess whose files may not grow past 4 KiB (EFBIG)."""
    folder = tmp_path / "disk"
    mounted = mount_tmpfs(folder, "size=192k")
    try:
        yield folder, mounted
    finally:
        if mounted:
            unmount(folder)


@pytest.fixture()
def read_only(tmp_path):
    """A folder nothing can be written to: a read-only tmpfs for root (whom permissions do not
    stop), a mode-555 folder for anyone else."""
    folder = tmp_path / "read_only"
    if os.geteuid() == 0:
        if not mount_tmpfs(folder, "ro,size=64k"):
            pytest.skip("root ignores permissions, and no tmpfs can be mounted here")
        try:
            yield folder
        finally:
            unmount(folder)
    else:
        folder.mkdir()
        folder.chmod(0o555)
        try:
            yield folder
        finally:
            folder.chmod(0o755)


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory) -> Path:
    from clonedrive.network.tiny_model import build_tiny_model

    path = tmp_path_factory.mktemp("model") / "tiny.keras"
    build_tiny_model().save(path)
    return path


FIXTURES = Path(__file__).resolve().parent / "fixtures" / "udacity"


def writing_probes(root: Path) -> dict[str, list]:
    return {
        "record": ["record", "--track", "lake", "--seconds", "4", "--no-scenery",
                   "--out", root / "rec"],
        "train": ["train", FIXTURES / "stationary", "--model", "fast", "--epochs", "1",
                  "--out", root / "train", "--json"],
        "tracks": ["tracks", "--track", "lake", "--no-strip", "--out", root / "maps"],
    }


def test_a_full_disk_gets_one_line_naming_the_path(full_disk, capsys):
    disk, small = full_disk
    probes = writing_probes(disk)
    if small:
        results = [run_cli(capsys, *argv)[::2] for argv in probes.values()]
    else:
        results = run_limited(*probes.values(), file_size_limit=4096)
    for name, (code, err) in zip(probes, results, strict=True):
        assert_one_clear_line(code, err)
        assert str(disk) in err and ("disk full" in err or "file too large" in err), (name, err)
    # What was recorded before the disk filled is whole: every row's images decode.
    log = read_driving_log(disk / "rec", verify_images="decode")
    assert log.skipped == []


def test_a_read_only_folder_gets_one_line_naming_the_path(read_only, tiny_model, tmp_path,
                                                          capsys):
    circle = tmp_path / "circle.json"
    circle.write_text(json.dumps(circle_track("circle")))
    probes = writing_probes(read_only)
    probes["evaluate"] = ["evaluate", tiny_model, "--track", circle, "--laps", "1",
                          "--out", read_only / "eval"]
    probes["drive"] = ["drive", tiny_model, read_only / "frames", "--port", "0"]
    for name, argv in probes.items():
        code, _, err = run_cli(capsys, *argv)
        assert_one_clear_line(code, err)
        assert str(read_only) in err, (name, err)
        assert "socket" not in err and "listen" not in err, (name, err)
    assert not any(read_only.iterdir())


def test_record_out_naming_an_existing_file_is_refused(tmp_path, capsys):
    existing = tmp_path / "notes.txt"
    existing.write_text("keep me")
    code, _, err = run_cli(capsys, "record", "--track", "lake", "--seconds", "1",
                           "--no-scenery", "--out", existing)
    assert_one_clear_line(code, err)
    assert "is an existing file" in err and str(existing) in err
    assert existing.read_text() == "keep me"


# --------------------------------------------------------------------------- drive server

def upgrade_status(port: int, *headers: str) -> int:
    """The HTTP status of a raw WebSocket upgrade to the drive server."""
    lines = ["GET /socket.io/?EIO=4&transport=websocket HTTP/1.1", f"Host: 127.0.0.1:{port}",
             "Upgrade: websocket", "Connection: Upgrade",
             "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==", "Sec-WebSocket-Version: 13",
             *headers]
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        return int(sock.makefile("rb").readline().split()[1])


def test_drive_refuses_browser_origins_and_reaps_idle_clients(tiny_model):
    """The real ``clonedrive drive`` process: a web page's upgrade is refused, a client that
    only pings holds the one slot until it is closed, then the simulator gets in."""
    command = [sys.executable, "-m", "clonedrive.cli", "drive", str(tiny_model), "--port", "0",
               "--max-connections", "1", "--idle-timeout", "1", "--status-every", "0"]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path), PYTHONUNBUFFERED="1")
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, env=env)
    jpeg = sorted((FIXTURES / "stationary" / "IMG").glob("center_*.jpg"))[0].read_bytes()

    async def probes(port: int) -> tuple:
        url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
        origin = await asyncio.to_thread(upgrade_status, port, "Origin: https://evil.example")
        async with connect(url, compression=None) as idle:  # answers pings, sends no telemetry
            await idle.recv(), await idle.recv()
            busy = await asyncio.to_thread(upgrade_status, port)
            try:
                while True:
                    await idle.send("2")
                    await asyncio.wait_for(idle.recv(), 30)
                    await asyncio.sleep(0.05)
            except ConnectionClosed as closed:
                idle_code = closed.rcvd.code if closed.rcvd else None
        async with connect(url, compression=None) as simulator:
            await simulator.recv(), await simulator.recv()
            await simulator.send(protocol.telemetry_frame(0.0, 0.0, 0.0, jpeg))
            reply = await asyncio.wait_for(simulator.recv(), 30)
        return origin, busy, idle_code, reply

    try:
        port = None
        for line in process.stderr:
            found = re.search(r"listening on ws://127\.0\.0\.1:(\d+)/socket\.io/", line)
            if found:
                port = int(found[1])
                break
        assert port is not None, "the server never said where it listens"
        origin, busy, idle_code, reply = asyncio.run(probes(port))
    finally:
        process.send_signal(signal.SIGINT)
        _, rest = process.communicate(timeout=60)
    assert (origin, busy, idle_code) == (403, 503, IDLE_CLOSE_CODE)
    assert protocol.decode_event(reply)[0] == "steer"
    assert process.returncode == 0 and "Traceback" not in rest
    assert "2 refused, 1 closed idle" in rest


# --------------------------------------------------------------------------- bad numbers

@pytest.mark.parametrize("argv", [
    ["evaluate", "model.keras", "--speed", "nan"],
    ["evaluate", "model.keras", "--speed=-5"],
    ["evaluate", "model.keras", "--unseen", "1", "--unseen-speed", "inf"],
    ["drive", "model.keras", "--speed", "nan"],
    ["drive", "model.keras", "--idle-timeout", "nan"],
    ["record", "--out", "never", "--speed", "nan"],
    ["record", "--out", "never", "--noise", "nan"],
])
def test_non_finite_and_negative_speeds_are_refused(tmp_path, capsys, argv):
    code, _, err = run_cli(capsys, *[str(tmp_path / arg) if arg in ("model.keras", "never")
                                     else arg for arg in argv])
    assert_one_clear_line(code, err)
    assert not any(tmp_path.iterdir())  # refused before anything was written
