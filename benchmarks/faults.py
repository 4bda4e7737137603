"""Issue 14's hardening targets, measured: bad input and faults tried as a careful user and an
attacker would, each as a real ``clonedrive`` process.

Run: python benchmarks/faults.py [--realdata ../shared/realdata]   (a few minutes; as root it
also mounts small tmpfs folders for the full-disk and read-only probes).

For every probe it records the exit status, whether stderr holds a traceback, how many lines
it printed there, the peak resident memory of the process, and every file it created outside
its ``--out`` inside the sandbox (plus the escape targets the hostile names aim at). Then: two
recorders into one folder at once, a browser-origin upgrade and idle clients against the drive
server, and the center-only real recording.

Targets: 0 tracebacks, 0 files outside --out, second recorder refused, browser origin refused,
idle sessions reaped, every row of lake_rikki_center usable, peak memory bounded (the largest
figure is printed; an unbounded input once took 24 GB). Issue 37's probes follow
(:mod:`faults_round3`: two simulators at once, a client that stops reading, same-origin and
doubled headers, two writers, outputs over inputs, SIGTERM, planted report paths, huge images).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "tests" / "fixtures" / "udacity"
#: A probe using more than this is reported as unbounded [MB].
MEMORY_BOUND_MB = 4096


def circle(name: str, radius_m: float = 60.0, count: int = 40, **extra) -> dict:
    angles = [2 * math.pi * i / count for i in range(count)]
    return {"name": name, "version": 1, "theme": "lake", "width_m": 8.0, "closed": True,
            "centerline": [[radius_m * math.cos(a), radius_m * math.sin(a), 0.0]
                           for a in angles], **extra}


def files_under(folder: Path) -> set[Path]:
    return {path for path in folder.rglob("*") if path.is_file() or path.is_symlink()}


def run_probe(name: str, argv: list, sandbox: Path, out: Path | None, *, cwd: Path | None = None,
              expect_ok: bool = False, escapes: tuple[Path, ...] = ()) -> dict:
    """Run ``clonedrive ARGV`` and measure it."""
    before = files_under(sandbox)
    escaped_before = {path for path in escapes if os.path.lexists(path)}
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    with tempfile.TemporaryFile() as err_file:
        process = subprocess.Popen([sys.executable, "-m", "clonedrive.cli", *map(str, argv)],
                                   stdout=subprocess.DEVNULL, stderr=err_file, cwd=cwd, env=env)
        _, status, usage = os.wait4(process.pid, 0)
        process.returncode = os.waitstatus_to_exitcode(status)
        err_file.seek(0)
        err = err_file.read().decode("utf-8", "replace")
    new = files_under(sandbox) - before
    outside = sorted(str(path) for path in new
                     if out is None or not path.resolve().is_relative_to(out.resolve()))
    outside += [str(path) for path in escapes
                if os.path.lexists(path) and path not in escaped_before]
    lines = [line for line in err.splitlines() if line.strip()]
    result = {
        "probe": name, "rc": process.returncode, "traceback": "Traceback" in err,
        "stderr_lines": len(lines), "peak_rss_mb": round(usage.ru_maxrss / 1024, 1),
        "outside_out": outside, "message": lines[-1][:160] if lines else "",
    }
    result["ok"] = (not result["traceback"] and not outside
                    and (process.returncode == 0 if expect_ok
                         else process.returncode != 0 and len(lines) == 1))
    return result


def mount_tmpfs(folder: Path, options: str) -> bool:
    folder.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    return subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)],
                          capture_output=True).returncode == 0


def build_inputs(sandbox: Path) -> dict[str, Path]:
    """The hostile files the probes use."""
    inputs = sandbox / "inputs"
    inputs.mkdir()
    paths: dict[str, Path] = {}

    def put(name: str, content: bytes) -> None:
        paths[name] = inputs / name
        paths[name].write_bytes(content)

    put("circle.json", json.dumps(circle("circle")).encode())
    put("huge_circle.json", json.dumps(circle("huge", radius_m=1e7)).encode())
    put("utf16.json", json.dumps(circle("u")).encode("utf-16"))
    put("digits.json", b'{"name": "d", "width_m": ' + b"7" * 5000 + b"}")
    put("deep.json", b"[" * 100_000 + b"]" * 100_000)
    put("version99.json", json.dumps(circle("v", version=99)).encode())
    put("jpeg.json", (FIXTURES / "stationary" / "IMG").joinpath(
        sorted(p.name for p in (FIXTURES / "stationary" / "IMG").iterdir())[0]).read_bytes())
    put("escape_name.json", json.dumps(circle("../../../../tmp/clonedrive-escaped")).encode())
    put("absolute_name.json", json.dumps(circle(str(sandbox / "absolute-escape"))).encode())
    paths["folder.json"] = inputs / "folder.json"
    paths["folder.json"].mkdir()
    paths["big.json"] = inputs / "big.json"
    with open(paths["big.json"], "wb") as handle:
        handle.truncate(64 << 20)
    # Logs that are not logs, and one row naming an image no file system allows.
    for name, content in (("utf16_log", "a,b,c,0,0,0,1\n".encode("utf-16")),
                          ("jpeg_log", paths["jpeg.json"].read_bytes())):
        (inputs / name).mkdir()
        (inputs / name / "driving_log.csv").write_bytes(content)
        paths[name] = inputs / name
    long_name = inputs / "long_name_log"
    shutil.copytree(FIXTURES / "stationary", long_name)
    lines = (long_name / "driving_log.csv").read_text().splitlines(keepends=True)
    lines[3] = "C:\\data\\IMG\\" + "c" * 300 + ".jpg" + lines[3][lines[3].index(","):]
    (long_name / "driving_log.csv").write_text("".join(lines))
    paths["long_name_log"] = long_name
    (inputs / "notes.txt").write_text("an existing file")
    paths["notes.txt"] = inputs / "notes.txt"
    # A tiny model for the probes that need one.
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    paths["model"] = inputs / "tiny.keras"
    subprocess.run([sys.executable, "-c",
                    "import sys; from clonedrive.base.keras_backend import choose_backend; "
                    "choose_backend(); from clonedrive.network.tiny_model import "
                    "build_tiny_model; build_tiny_model().save(sys.argv[1])",
                    str(paths["model"])], check=True, env=env)
    return paths


def probes(sandbox: Path, paths: dict[str, Path]) -> list[dict]:
    results = []
    outs = sandbox / "outs"
    work = sandbox / "work"
    work.mkdir()

    def probe(name: str, argv: list, out: Path | None, **options) -> None:
        result = run_probe(name, argv, sandbox, out, **options)
        results.append(result)
        mark = "ok " if result["ok"] else "BAD"
        print(f"  {mark} {name:<28} rc {result['rc']:>3}  {result['peak_rss_mb']:>7.0f} MB  "
              f"{result['message'][:90]}", flush=True)

    model = paths["model"]
    # Paths inside --out, whatever the names.
    out = outs / "tracks_names"
    probe("tracks: hostile names", ["tracks", "--track", paths["escape_name.json"], "--track",
                                    paths["absolute_name.json"], "--no-strip", "--out", out],
          out, expect_ok=True,
          escapes=(Path("/tmp/clonedrive-escaped_map.png"), sandbox / "absolute-escape_map.png"))
    out = outs / "eval_abs"
    probe("evaluate: absolute --track", ["evaluate", model, "--track", paths["circle.json"],
                                         "--laps", "1", "--speed", "30", "--out", out],
          out, expect_ok=True, escapes=(paths["circle.json"].with_suffix(".png"),))
    out = outs / "eval_rel"
    probe("evaluate: ../ --track", ["evaluate", model, "--track", "../inputs/circle.json",
                                    "--laps", "1", "--speed", "30", "--out", out],
          out, cwd=work, expect_ok=True)
    # Track files.
    for name in ("huge_circle.json", "utf16.json", "digits.json", "deep.json",
                 "version99.json", "jpeg.json", "folder.json", "big.json"):
        probe(f"tracks: {name}", ["tracks", "--track", paths[name], "--no-images"], None)
    out = outs / "record_huge"
    probe("record: huge_circle.json", ["record", "--track", paths["huge_circle.json"],
                                       "--out", out], out)
    # Numbers.
    for speed in ("nan", "-5"):
        out = outs / f"eval_speed{speed}"
        probe(f"evaluate --speed {speed}", ["evaluate", model, f"--speed={speed}", "--out", out],
              out)
    # Logs.
    for name in ("utf16_log", "jpeg_log"):
        probe(f"check: {name}", ["check", paths[name]], None)
    probe("check: 300-char image name", ["check", paths["long_name_log"]], None, expect_ok=True)
    out = outs / "train_long_name"
    probe("train: 300-char image name", ["train", paths["long_name_log"], "--model", "fast",
                                         "--epochs", "1", "--out", out], out, expect_ok=True)
    # Where things are written.
    probe("record --out a file", ["record", "--seconds", "1", "--no-scenery", "--out",
                                  paths["notes.txt"]], None)
    probe("drive --host 256.1.1.1", ["drive", model, "--host", "256.1.1.1"], None)
    disk = sandbox / "full_disk"
    if mount_tmpfs(disk, "size=192k"):
        try:
            for name, argv in (
                    ("record", ["record", "--seconds", "5", "--no-scenery", "--out", disk / "r"]),
                    ("train", ["train", FIXTURES / "stationary", "--model", "fast", "--epochs",
                               "1", "--out", disk / "t"]),
                    ("tracks", ["tracks", "--track", "lake", "--no-strip", "--out", disk / "m"])):
                probe(f"full disk: {name}", argv, disk)
        finally:
            subprocess.run(["umount", str(disk)], check=False)
    else:
        print("  (no tmpfs: full-disk probes skipped; tests/test_faults.py uses a file-size "
              "limit instead)")
    read_only = sandbox / "read_only"
    if mount_tmpfs(read_only, "ro,size=64k"):
        try:
            for name, argv in (
                    ("record", ["record", "--seconds", "1", "--no-scenery", "--out",
                                read_only / "r"]),
                    ("train", ["train", FIXTURES / "stationary", "--model", "fast", "--epochs",
                               "1", "--out", read_only / "t"]),
                    ("tracks", ["tracks", "--track", "lake", "--no-strip", "--out",
                                read_only / "m"]),
                    ("evaluate", ["evaluate", model, "--track", paths["circle.json"],
                                  "--out", read_only / "e"]),
                    ("drive image folder", ["drive", model, read_only / "frames", "--port", "0"])):
                probe(f"read-only: {name}", argv, read_only)
        finally:
            subprocess.run(["umount", str(read_only)], check=False)
    else:
        print("  (no read-only tmpfs: read-only probes skipped)")
    return results


def two_recorders(sandbox: Path) -> dict:
    """Start one recorder, then a second into the same folder while the first writes."""
    out = sandbox / "outs" / "two_recorders"
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    base = [sys.executable, "-m", "clonedrive.cli", "record", "--no-scenery", "--out", str(out),
            "--json"]
    first = subprocess.Popen([*base, "--track", "lake", "--seconds", "3600"], env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while not (out / "driving_log.csv").exists() and time.monotonic() < deadline \
                and first.poll() is None:
            time.sleep(0.05)
        second = subprocess.run([*base, "--track", "mountain", "--seconds", "3"], env=env,
                                capture_output=True, text=True)
    finally:
        first.send_signal(signal.SIGINT)
        printed, _ = first.communicate()
    sys.path.insert(0, str(ROOT / "src"))
    from clonedrive.data.driving_log import read_driving_log

    log = read_driving_log(out, verify_images="decode")
    rows = json.loads(printed)["rows"] if printed.strip() else None
    return {"second_rc": second.returncode, "second_message": second.stderr.strip()[:200],
            "second_refused": second.returncode != 0 and "another recorder" in second.stderr,
            "first_rows": rows, "log_rows": log.total_rows, "usable": len(log.rows),
            "shared_images": len(log.shared_images()),
            "images": len(list((out / "IMG").glob("*.jpg")))}


def drive_server_probes() -> dict:
    """A browser-origin upgrade, and two clients that only ping against a 3-slot server."""
    sys.path.insert(0, str(ROOT / "src"))
    import socket

    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    from clonedrive.udacity.server import DriveServer

    class Fixed:
        def reset(self) -> None:
            pass

        def act(self, image, speed):
            return 0.0, 0.2

    def status(port: int, *headers: str) -> int:
        lines = ["GET /socket.io/?EIO=4&transport=websocket HTTP/1.1",
                 f"Host: 127.0.0.1:{port}", "Upgrade: websocket", "Connection: Upgrade",
                 "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==", "Sec-WebSocket-Version: 13",
                 *headers]
        with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
            sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
            return int(sock.makefile("rb").readline().split()[1])

    async def idle(port: int) -> float:
        url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
        start = time.monotonic()
        async with connect(url, compression=None) as ws:
            try:
                while True:
                    await ws.send("2")
                    await asyncio.wait_for(ws.recv(), 30)
                    await asyncio.sleep(0.05)
            except ConnectionClosed:
                return time.monotonic() - start

    async def scenario(port: int) -> tuple:
        tasks = [asyncio.create_task(idle(port)) for _ in range(3)]
        await asyncio.sleep(0.5)
        busy = await asyncio.to_thread(status, port)
        closed_after = await asyncio.gather(*tasks)
        after = await asyncio.to_thread(status, port)
        return busy, closed_after, after

    timeout_s = 2.0
    with DriveServer(Fixed(), port=0, status_interval_s=0, max_connections=3,
                     idle_timeout_s=timeout_s) as server:
        origin = status(server.port, "Origin: https://evil.example")
        plain = status(server.port)
        busy, closed_after, after = asyncio.run(scenario(server.port))
        stats = server.stats()
    return {"origin_status": origin, "no_origin_status": plain, "origin_refused": origin == 403,
            "busy_status": busy, "idle_closed": stats.idle_closed,
            "idle_closed_after_s": [round(value, 2) for value in closed_after],
            "idle_timeout_s": timeout_s, "status_after_reaping": after,
            "idle_reaped": after == 101 and len(closed_after) == 3}


def center_only(realdata: Path) -> dict | None:
    folder = realdata / "lake_rikki_center"
    if not (folder / "driving_log.csv").is_file():
        return None
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    result = subprocess.run([sys.executable, "-m", "clonedrive.cli", "check", str(folder),
                             "--json"], capture_output=True, text=True, env=env, check=True)
    summary = json.loads(result.stdout)
    sys.path.insert(0, str(ROOT / "src"))
    from clonedrive.data.recipe import default_recipe_for, expand

    samples = expand(default_recipe_for([folder]))
    return {"rows": summary["rows"], "usable_rows": summary["usable_rows"],
            "side_images_missing": summary["side_images_missing"],
            "skipped": summary["skipped"], "training_samples": len(samples)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--realdata", type=Path, default=ROOT.parent / "shared" / "realdata")
    args = parser.parse_args()
    sandbox = Path(tempfile.mkdtemp(prefix="clonedrive-faults-"))
    try:
        print(f"sandbox {sandbox}")
        paths = build_inputs(sandbox)
        print("probes (each a clonedrive process):")
        results = probes(sandbox, paths)
        print("two recorders into one folder:")
        recorders = two_recorders(sandbox)
        print(f"  second refused: {recorders['second_refused']} ({recorders['second_message']})")
        print(f"  log: {recorders['log_rows']} rows, {recorders['usable']} usable, "
              f"{recorders['images']} images, {recorders['shared_images']} shared")
        print("drive server:")
        server = drive_server_probes()
        print(f"  browser origin: HTTP {server['origin_status']} (no origin: "
              f"{server['no_origin_status']}); 3 idle clients on 3 slots: new client "
              f"{server['busy_status']}, idle ones closed after {server['idle_closed_after_s']} s "
              f"(timeout {server['idle_timeout_s']} s), then {server['status_after_reaping']}")
        centre = center_only(args.realdata)
        if centre is not None:
            print(f"center-only lake_rikki_center: {centre['usable_rows']} of {centre['rows']} "
                  f"rows usable ({centre['side_images_missing']} without side images), "
                  f"{centre['training_samples']} training samples")
        print("issue 37 probes:")
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from faults_round3 import round3

        third = round3()
    finally:
        shutil.rmtree(sandbox, ignore_errors=True)
    tracebacks = sum(result["traceback"] for result in results)
    outside = sum(len(result["outside_out"]) for result in results)
    peak = max(result["peak_rss_mb"] for result in results)
    failed = [result["probe"] for result in results if not result["ok"]]
    print(f"{len(results)} probes: {tracebacks} tracebacks (target 0), {outside} files outside "
          f"--out (target 0), largest peak memory {peak:.0f} MB (bound {MEMORY_BOUND_MB} MB), "
          f"{len(failed)} not as expected{': ' + ', '.join(failed) if failed else ''}")
    print(json.dumps({
        "probes": len(results), "tracebacks": tracebacks, "files_outside_out": outside,
        "peak_rss_mb_max": peak, "memory_bounded": peak < MEMORY_BOUND_MB,
        "probes_not_as_expected": failed,
        "second_recorder_refused": recorders["second_refused"],
        "two_recorder_shared_images": recorders["shared_images"],
        "origin_refused": server["origin_refused"], "idle_reaped": server["idle_reaped"],
        "center_only_usable_rows": centre["usable_rows"] if centre else None,
        "center_only_rows": centre["rows"] if centre else None,
        "round3": third,
    }))


if __name__ == "__main__":
    main()
