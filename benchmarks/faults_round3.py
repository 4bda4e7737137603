"""Issue 37's probes for benchmarks/faults.py: one state per simulator, same-origin Python
clients, doubled headers, one writer per output, outputs over inputs, SIGTERM, planted report
paths and huge images. Each is a real ``clonedrive`` process or a real socket client.

It also runs the later probes of ``faults_round3_bounds`` (hostile model files and logs, counts,
a full disk) and ``faults_round3_folders`` (planted links, run folders, names, small
tracebacks, replay and web claims), and totals them: tracebacks, files changed outside the named
folders, the largest peak memory.

Run alone: python benchmarks/faults_round3.py (prints its figures, then one line of JSON).
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "tests" / "fixtures" / "udacity"
ENV = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
CLI = [sys.executable, "-m", "clonedrive.cli"]
#: Runs a command and prints its peak memory [KiB] last on stderr, on a line of its own even
#: when the command left a progress bar's line unfinished. A child forked from this
#: process (Keras loaded) would count this process's pages as its own until it execs.
_MEASURED = ("import resource, subprocess, sys\n"
             "status = subprocess.run(sys.argv[1:]).returncode\n"
             "print('', resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, sep='\\n',\n"
             "      file=sys.stderr)\n"
             "sys.exit(status)\n")


def measured(*argv: object) -> dict:
    """Run ``clonedrive ARGV`` from a small launcher: exit status, output, peak memory."""
    process = subprocess.run([sys.executable, "-c", _MEASURED, *CLI, *map(str, argv)],
                             env=ENV, capture_output=True, text=True)
    *lines, peak_kib = process.stderr.strip().splitlines()
    return {"rc": process.returncode, "output": process.stdout + "\n".join(lines),
            "peak_rss_mb": round(int(peak_kib) / 1024, 1)}
WAIT_S = 300.0


def _frames() -> dict[str, list[str]]:
    jpegs = sorted((FIXTURES / "stationary" / "IMG").glob("center_*.jpg"))
    frames = {"a": [], "b": []}
    for index, path in enumerate(jpegs * 2):
        image = base64.b64encode(path.read_bytes()).decode("ascii")
        for car, speed in (("a", 2.0 * index), ("b", 30.0 - 3.0 * index)):
            frames[car].append('42["telemetry",{"steering_angle":"0","throttle":"0",'
                               f'"speed":"{speed:.4f}","image":"{image}"}}]')
    return frames


def two_simulators(model) -> dict:
    """Replies to two cars at once against each car alone (steering filter 1 s, hold)."""
    from websockets.asyncio.client import connect

    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.udacity.server import DriveServer

    async def drive(port: int, cars: dict[str, list[str]]) -> dict[str, list[str]]:
        url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
        sockets = {car: await connect(url, compression=None) for car in cars}
        for ws in sockets.values():
            await ws.recv(), await ws.recv()
        replies = {car: [] for car in cars}
        for step in range(len(next(iter(cars.values())))):
            for car, ws in sockets.items():
                await ws.send(cars[car][step])
            for car, ws in sockets.items():
                replies[car].append(await ws.recv())
        for ws in sockets.values():
            await ws.close()
        return replies

    def serve(cars):
        policy = NetworkPolicy(model, steering_filter_s=1.0, steering_hold=0.002)
        with DriveServer(policy, port=0, status_interval_s=0) as server:
            return asyncio.run(drive(server.port, cars))

    frames = _frames()
    alone = {car: serve({car: frames[car]})[car] for car in frames}
    together = serve(frames)
    differing = sum(a != b for car in frames for a, b in zip(alone[car], together[car],
                                                               strict=True))
    return {"frames_per_car": len(frames["a"]), "replies_differing": differing}


def stalled_reader() -> dict:
    """A client that stops reading (its pongs pile up): seconds until the server drops it."""
    from websockets.asyncio.client import connect

    from clonedrive.udacity.server import DriveServer

    class Still:
        def reset(self) -> None:
            pass

        def act(self, image, speed):
            return 0.0, 0.0

    async def flood(port: int) -> None:
        url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
        async with connect(url, compression=None, max_queue=1, max_size=None,
                           ping_interval=None) as ws:
            try:
                for _ in range(200):
                    await asyncio.wait_for(ws.send("2" + "x" * 500_000), WAIT_S)
            except Exception:  # noqa: BLE001 - closed by the server: what is measured
                pass

    timeout_s = 2.0
    with DriveServer(Still(), port=0, status_interval_s=0, idle_timeout_s=timeout_s) as server:
        start = time.monotonic()
        asyncio.run(flood(server.port))
        while server.stats().active_connections and time.monotonic() - start < WAIT_S:
            time.sleep(0.01)
        closed_after = time.monotonic() - start
        stats = server.stats()
    return {"idle_timeout_s": timeout_s, "closed_after_s": round(closed_after, 2),
            "idle_closed": stats.idle_closed}


def _status(port: int, *headers: str) -> int:
    lines = ["GET /socket.io/?EIO=4&transport=websocket HTTP/1.1", *headers,
             "Upgrade: websocket", "Connection: Upgrade",
             "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==", "Sec-WebSocket-Version: 13"]
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        return int(sock.makefile("rb").readline().split()[1])


def origins_and_headers() -> dict:
    import websocket

    from clonedrive.udacity.server import DriveServer

    class Fixed:
        def reset(self) -> None:
            pass

        def act(self, image, speed):
            return 0.0, 0.2

    with DriveServer(Fixed(), port=0, status_interval_s=0) as server:
        url = f"ws://127.0.0.1:{server.port}/socket.io/?EIO=4&transport=websocket"
        client = websocket.create_connection(url, timeout=30)
        own_origin = client.getstatus()
        client.close()
        host = f"Host: 127.0.0.1:{server.port}"
        foreign = _status(server.port, host, "Origin: https://evil.example")
        two_hosts = _status(server.port, host, host)
        two_origins = _status(server.port, host, f"Origin: http://127.0.0.1:{server.port}",
                              "Origin: https://evil.example")
    return {"websocket_client_default": own_origin, "foreign_origin": foreign,
            "two_host_headers": two_hosts, "two_origin_headers": two_origins}


def run_cli(*argv: object) -> dict:
    process = subprocess.Popen([*CLI, *map(str, argv)], env=ENV, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
    _, err = process.communicate()
    return {"rc": process.returncode, "traceback": "Traceback" in err,
            "message": (err.strip().splitlines() or [""])[-1][:200]}


def writers_and_inputs(sandbox: Path, model_path: Path) -> dict:
    """A second evaluate into a folder an evaluate writes; ensemble and train over inputs."""
    out = sandbox / "eval"
    first = subprocess.Popen([*CLI, "evaluate", model_path, "--track", "lake", "--laps", "50",
                              "--workers", "1", "--no-scenery", "--out", out], env=ENV,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        lock = out / ".clonedrive-writer.lock"
        start = time.monotonic()
        while not lock.exists() and first.poll() is None and time.monotonic() - start < WAIT_S:
            time.sleep(0.05)
        second = run_cli("evaluate", model_path, "--track", "mountain", "--laps", "1",
                         "--out", out)
    finally:
        first.send_signal(signal.SIGTERM)
        first.communicate()
    member = sandbox / "a.keras"
    shutil.copy(model_path, member)
    ensemble = run_cli("ensemble", member, model_path, "--out", member)
    recording = sandbox / "rec"
    shutil.copytree(FIXTURES / "stationary", recording)
    train = run_cli("train", recording, "--out", recording / "run", "--epochs", "1")
    return {"second_evaluate": second, "first_evaluate_rc": first.returncode,
            "ensemble_over_member": ensemble, "train_into_recording": train}


def sigterm_workers(sandbox: Path, model_path: Path) -> dict:
    """SIGTERM to evaluate --workers 2: its exit status and the workers left after it."""
    process = subprocess.Popen([*CLI, "evaluate", model_path, "--track", "lake", "--unseen", "4",
                                "--laps", "20", "--unseen-laps", "20", "--workers", "2",
                                "--batch", "1", "--no-scenery", "--out", sandbox / "term"],
                               env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                               text=True)
    start = time.monotonic()
    workers: set[int] = set()
    while not workers and process.poll() is None and time.monotonic() - start < WAIT_S:
        workers = _children(process.pid)
        time.sleep(0.1)
    process.send_signal(signal.SIGTERM)
    process.communicate()
    stopped = time.monotonic()
    while any(Path(f"/proc/{pid}").exists() for pid in workers) \
            and time.monotonic() - stopped < 120:
        time.sleep(0.05)
    left = [pid for pid in workers if Path(f"/proc/{pid}").exists()]
    return {"rc": process.returncode, "workers": len(workers), "workers_left": len(left),
            "workers_gone_after_s": round(time.monotonic() - stopped, 2)}


def _children(parent: int) -> set[int]:
    found = set()
    for entry in Path("/proc").iterdir():
        try:
            status = (entry / "status").read_text() if entry.name.isdigit() else ""
            command = (entry / "cmdline").read_bytes() if status else b""
        except OSError:
            continue
        if f"\nPPid:\t{parent}\n" in status and b"spawn_main" in command:
            found.add(int(entry.name))
    return found


def planted_report(sandbox: Path) -> dict:
    secret = sandbox / "secret.png"
    shutil.copy(sorted((FIXTURES / "stationary" / "IMG").glob("*.jpg"))[0], secret)
    run = sandbox / "shared_run"
    (run / "eval").mkdir(parents=True)
    (run / "loss.png").symlink_to(secret)
    (run / "history.csv").write_text("epoch,loss,val_loss\n0,0.5,0.6\n", encoding="utf-8")
    runs = [{"track": "lake", "speed_mph": 20.0, "laps_completed": 1, "laps_target": 1,
             "interventions": 0, "map_png": "/etc/hostname", "video": "../../secret.png"}]
    (run / "eval" / "eval.json").write_text(json.dumps({"runs": runs, "complete": True}))
    out = sandbox / "report_out"
    result = measured("report", run, "--out", out)
    planted = {secret.read_bytes()}
    if Path("/etc/hostname").is_file():
        planted.add(Path("/etc/hostname").read_bytes())
    carried = [str(path) for path in out.rglob("*")
               if path.is_file() and path.read_bytes() in planted]
    notes = [line for line in result.pop("output", "").splitlines() if "Refused" in line]
    return {**result, "refusals_named": len(notes), "files_carried_from_outside": carried}


def huge_png(sandbox: Path) -> dict:
    """A 2.6 MB PNG of 30000x30000 grey pixels named center.jpg, through check."""
    recording = sandbox / "huge_png"
    shutil.copytree(FIXTURES / "stationary", recording)
    target = sorted((recording / "IMG").glob("center_*.jpg"))[0]
    compressor, body = zlib.compressobj(9), []
    for _ in range(30000):  # each row: one filter byte and 30000 grey pixels
        body.append(compressor.compress(b"\0" * 30001))
    body.append(compressor.flush())
    data = b"".join(body)
    ihdr = struct.pack(">IIBBBBB", 30000, 30000, 8, 0, 0, 0, 0)
    png = b"\x89PNG\r\n\x1a\n"
    for kind, chunk in ((b"IHDR", ihdr), (b"IDAT", data), (b"IEND", b"")):
        png += struct.pack(">I", len(chunk)) + kind + chunk + struct.pack(
            ">I", zlib.crc32(kind + chunk))
    target.write_bytes(png)
    result = measured("check", recording)
    return {"png_mb": round(len(png) / 1e6, 1), "rc": result["rc"],
            "peak_rss_mb": result["peak_rss_mb"], "names_limit": "4096x4096" in result["output"],
            "traceback": "Traceback" in result["output"]}


def unseen_count() -> dict:
    result = measured("evaluate", "model.keras", "--unseen", "1000000000")
    return {"rc": result["rc"], "message": result["output"].strip()[:160],
            "peak_rss_mb": result["peak_rss_mb"]}


def round3() -> dict:
    """Every probe above, printed; returns the figures."""
    sys.path.insert(0, str(ROOT / "src"))
    from clonedrive.network.tiny_model import build_tiny_model

    sandbox = Path(tempfile.mkdtemp(prefix="clonedrive-faults3-"))
    try:
        model = build_tiny_model(seed=3)
        model_path = sandbox / "tiny.keras"
        model.save(model_path)
        figures = {"two_simulators": two_simulators(model), "stalled_reader": stalled_reader(),
                   "origins_and_headers": origins_and_headers(),
                   "writers_and_inputs": writers_and_inputs(sandbox, model_path),
                   "sigterm": sigterm_workers(sandbox, model_path),
                   "planted_report": planted_report(sandbox), "huge_png": huge_png(sandbox),
                   "unseen_count": unseen_count()}
        figures.update(later_probes(sandbox))
    finally:
        shutil.rmtree(sandbox, ignore_errors=True)
    for name, value in figures.items():
        print(f"  {name}: {json.dumps(value)}")
    figures["totals"] = probe_totals(figures)
    print(f"  totals: {json.dumps(figures['totals'])}")
    return figures


def later_probes(sandbox: Path) -> dict:
    """The probes of faults_round3_bounds (memory, full disk, counts) and
    faults_round3_folders (run folders, planted links, small tracebacks), each in a folder of
    its own."""
    from faults_round3_bounds import bounds
    from faults_round3_folders import folders

    (sandbox / "bounds").mkdir()
    (sandbox / "folders").mkdir()
    return {"bounds": bounds(sandbox / "bounds"), "folders": folders(sandbox / "folders")}


def probe_totals(figures: dict) -> dict:
    """Over every probe: how many printed a traceback, how many changed a file outside the
    folders they were given, and the largest peak memory [MB]."""
    tracebacks, outside, peaks = 0, 0, []

    def walk(value: object) -> None:
        nonlocal tracebacks, outside
        if isinstance(value, dict):
            tracebacks += value.get("traceback") is True
            outside += value.get("outside_file_changed") is True
            if isinstance(value.get("peak_rss_mb"), int | float):
                peaks.append(value["peak_rss_mb"])
            for item in value.values():
                walk(item)
        elif isinstance(value, list):
            for item in value:
                walk(item)

    walk(figures)
    return {"tracebacks": tracebacks, "outside_files_changed": outside,
            "max_peak_rss_mb": max(peaks, default=None), "probes_measured": len(peaks)}


if __name__ == "__main__":
    print("issue 37 probes:")
    print(json.dumps(round3()))
