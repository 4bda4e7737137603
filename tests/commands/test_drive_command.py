"""``clonedrive drive``: the drive.py drop-in, run as a real process."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from websockets.asyncio.client import connect

from clonedrive.cli import main
from clonedrive.udacity import protocol


def test_missing_model_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["drive", str(tmp_path / "nothing.keras"), "--port", "0"]) == 1
    assert "nothing.keras" in capsys.readouterr().err


def test_busy_port_is_named_before_the_model_loads(tiny_model_path: Path,
                                                   capsys: pytest.CaptureFixture) -> None:
    """A port another program holds is reported with the fix, and no model is loaded for it."""
    import socket

    with socket.create_server(("127.0.0.1", 0)) as holder:
        port = holder.getsockname()[1]
        # The model does not exist: had it been loaded first, the error would name the file.
        missing = tiny_model_path.parent / "absent.keras"
        assert main(["drive", str(missing), "--port", str(port)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"clonedrive drive: port {port} on 127.0.0.1 is already in use")
    assert "--port" in err and "absent.keras" not in err


def test_bad_arguments(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["drive", str(tmp_path / "m.keras"), "--speed", "80"]) == 2
    assert "--speed" in capsys.readouterr().err


def test_bad_steering_filter_or_hold_is_named(tiny_model_path: Path,
                                              capsys: pytest.CaptureFixture) -> None:
    """``drive`` and ``evaluate`` refuse a --steering-filter or --steering-hold the policy would
    refuse as a bad flag (argparse: exit 2), naming the limit."""
    model = str(tiny_model_path)
    for verb in ("drive", "evaluate"):
        with pytest.raises(SystemExit) as exit_hold:
            main([verb, model, "--steering-hold", "1.5"])
        assert exit_hold.value.code == 2
        assert "steering_hold must be a number in [0, 1)" in capsys.readouterr().err
        with pytest.raises(SystemExit) as exit_filter:
            main([verb, model, "--steering-filter", "-1"])
        assert exit_filter.value.code == 2
        assert "steering_filter_s (the steering low-pass's time constant) must be a number >= 0" \
            in capsys.readouterr().err


def test_serves_the_simulator_until_interrupted(tmp_path: Path, tiny_model_path: Path,
                                                recorded_jpeg: bytes) -> None:
    model = tiny_model_path
    frames = tmp_path / "run1"
    jpeg = recorded_jpeg
    command = [sys.executable, "-m", "clonedrive", "drive", str(model), str(frames)]
    command += ["--port", "0", "--speed", "15", "--slow-in-curves", "--steering-hold", "0.05"]
    process = subprocess.Popen(
        command, stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"}
    )
    try:
        port = None
        seen = []
        for line in process.stderr:
            seen.append(line)
            found = re.search(r"listening on ws://127\.0\.0\.1:(\d+)/socket\.io/", line)
            if found:
                port = int(found[1])
                break
        assert port is not None, "the server never said where it listens"
        # It says how it drives the model: the options given, on a file without settings.
        line = process.stderr.readline()
        assert "steering hold 0.05" in line and "slower in curves" in line, (seen, line)

        async def drive() -> list[str]:
            url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
            async with connect(url, compression=None) as ws:
                replies = [await ws.recv(), await ws.recv()]
                for _ in range(3):
                    await ws.send(protocol.telemetry_frame(0.0, 0.0, 0.0, jpeg))
                    replies.append(await asyncio.wait_for(ws.recv(), 30))
                return replies

        replies = asyncio.run(drive())
    finally:
        process.send_signal(signal.SIGINT)
        _, rest = process.communicate(timeout=30)
    assert process.returncode == 0, rest
    assert replies[1] == "40"
    for reply in replies[2:]:
        name, args = protocol.decode_event(reply)
        assert name == "steer" and set(args[0]) == {"steering_angle", "throttle"}
    assert "3 steer" in rest
    assert len(list(frames.glob("*.jpg"))) == 3
