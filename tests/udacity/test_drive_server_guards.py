"""The drive server's guards, over real sockets on 127.0.0.1: browser origins and foreign Host
headers are refused, idle connections are closed so the simulator is never locked out, saved
frames stop at the image folder's cap, and bad settings are refused before anything listens."""

from __future__ import annotations

import asyncio
import base64
import math
import os
import socket
from pathlib import Path

import numpy as np
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from clonedrive.cli import main
from clonedrive.udacity.server import DriveServer, DriveServerConfig
from clonedrive.udacity.server_config import IDLE_CLOSE_CODE

TIMEOUT_S = 10.0


class FixedPolicy:
    def reset(self) -> None:
        pass

    def act(self, image_rgb: np.ndarray, speed_mph: float) -> tuple[float, float]:
        return 0.1, 0.3


def telemetry(jpeg: bytes) -> str:
    image = base64.b64encode(jpeg).decode("ascii")
    return ('42["telemetry",{"steering_angle":"0.0000","throttle":"0.0000","speed":"1.0000",'
            f'"image":"{image}"}}]')


def upgrade_status(port: int, *headers: str, host: str | None = None) -> int:
    """The HTTP status a raw WebSocket upgrade request gets (Host and Origin as given)."""
    lines = ["GET /socket.io/?EIO=4&transport=websocket HTTP/1.1",
             f"Host: {host if host is not None else f'127.0.0.1:{port}'}",
             "Upgrade: websocket", "Connection: Upgrade",
             "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==", "Sec-WebSocket-Version: 13",
             *headers]
    with socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        status_line = sock.makefile("rb").readline().decode()
    return int(status_line.split()[1])


def test_browser_origins_are_refused_unless_allowed() -> None:
    allowed = "http://localhost:8000"
    with DriveServer(FixedPolicy(), port=0, status_interval_s=0,
                     allowed_origins=(allowed,)) as server:
        assert upgrade_status(server.port) == 101  # the simulator sends no Origin
        assert upgrade_status(server.port, "Origin: http://evil.example") == 403
        assert upgrade_status(server.port, "Origin: null") == 403  # sandboxed pages, files
        assert upgrade_status(server.port, f"Origin: {allowed}") == 101
        with pytest.raises(InvalidStatus) as refused:
            asyncio.run(_open(server.port, origin="http://evil.example"))
        assert refused.value.response.status_code == 403
        assert server.stats().refused == {"origin": 3}


async def _open(port: int, **options) -> None:
    url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
    async with connect(url, compression=None, open_timeout=TIMEOUT_S, **options) as ws:
        await asyncio.wait_for(ws.recv(), TIMEOUT_S)


def test_host_header_must_name_the_server() -> None:
    with DriveServer(FixedPolicy(), port=0, status_interval_s=0,
                     allowed_hosts=("mybox.local",)) as server:
        port = server.port
        for good in (f"127.0.0.1:{port}", f"localhost:{port}", "LOCALHOST", f"[::1]:{port}",
                     f"mybox.local:{port}"):
            assert upgrade_status(port, host=good) == 101, good
        # A DNS-rebinding page reaches 127.0.0.1 under its own name; another address is not us.
        for bad in (f"evil.example:{port}", "127.0.0.1.evil.example", f"10.1.2.3:{port}"):
            assert upgrade_status(port, host=bad) == 403, bad
        assert server.stats().refused == {"host": 3}


def test_on_every_interface_any_address_but_no_foreign_name() -> None:
    config = DriveServerConfig(host="0.0.0.0")
    assert config.host_allowed("10.1.2.3:4567") and config.host_allowed("[fe80::1]:4567")
    assert not config.host_allowed("evil.example:4567")
    assert DriveServerConfig(host="10.1.2.3").host_allowed("10.1.2.3:4567")
    assert not DriveServerConfig(host="10.1.2.3").host_allowed("10.9.9.9")


def test_idle_connections_are_closed_and_the_simulator_gets_in(recorded_jpeg: bytes) -> None:
    jpeg = recorded_jpeg
    """Two clients that only ping fill the server; they are closed after the idle timeout
    while a client sending telemetry all along keeps its connection."""
    idle_s = 1.0

    async def pinger(port: int) -> int:
        url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
        async with connect(url, compression=None) as ws:
            try:
                while True:
                    await ws.send("2")
                    await asyncio.wait_for(ws.recv(), TIMEOUT_S)  # handshake frames, then pongs
                    await asyncio.sleep(0.05)
            except ConnectionClosed as closed:
                return closed.rcvd.code if closed.rcvd else -1

    async def driver(port: int, seconds: float) -> int:
        url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
        replies = 0
        async with connect(url, compression=None) as ws:
            await ws.recv(), await ws.recv()
            loop = asyncio.get_running_loop()
            end = loop.time() + seconds
            while loop.time() < end:
                await ws.send(telemetry(jpeg))
                assert (await asyncio.wait_for(ws.recv(), TIMEOUT_S)).startswith('42["steer"')
                replies += 1
                await asyncio.sleep(0.05)
        return replies

    async def scenario(port: int) -> tuple[list[int], int, int, int]:
        drive = asyncio.create_task(driver(port, 4 * idle_s))
        await asyncio.sleep(0.3)
        pings = [asyncio.create_task(pinger(port)) for _ in range(2)]
        await asyncio.sleep(0.3)
        busy = await asyncio.to_thread(upgrade_status, port)  # every slot taken
        codes = await asyncio.gather(*pings)
        replies = await drive
        after = await asyncio.to_thread(upgrade_status, port)
        return codes, busy, replies, after

    with DriveServer(FixedPolicy(), port=0, status_interval_s=0, max_connections=3,
                     idle_timeout_s=idle_s) as server:
        codes, busy, replies, after = asyncio.run(scenario(server.port))
        stats = server.stats()
    assert busy == 503
    assert codes == [IDLE_CLOSE_CODE, IDLE_CLOSE_CODE]
    assert replies > 0 and stats.steer == replies  # the driving client was never cut off
    assert after == 101
    assert stats.idle_closed >= 2  # the two pingers (and the 101 probe that sent nothing)


def test_saved_frames_stop_at_the_image_folder_cap(tmp_path: Path, recorded_jpeg: bytes) -> None:
    jpeg = recorded_jpeg
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "earlier.bin").write_bytes(bytes(len(jpeg)))  # counted towards the cap
    cap_mb = 3.5 * len(jpeg) / 1e6  # room for the earlier file and two frames

    async def drive(port: int) -> None:
        url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
        async with connect(url, compression=None) as ws:
            await ws.recv(), await ws.recv()
            for _ in range(6):
                await ws.send(telemetry(jpeg))
                assert (await asyncio.wait_for(ws.recv(), TIMEOUT_S)).startswith('42["steer"')

    with DriveServer(FixedPolicy(), port=0, status_interval_s=0, image_folder=folder,
                     image_folder_max_mb=cap_mb) as server:
        asyncio.run(drive(server.port))
        stats = server.stats()
    assert stats.steer == 6  # driving goes on
    assert (stats.frames_saved, stats.frames_not_saved) == (2, 4)
    assert sum(path.stat().st_size for path in folder.iterdir()) <= cap_mb * 1e6


def test_an_image_folder_that_is_a_file_is_named_not_blamed_on_the_socket(tmp_path: Path
                                                                          ) -> None:
    (tmp_path / "frames").write_text("not a folder")
    server = DriveServer(FixedPolicy(), port=0, image_folder=tmp_path / "frames")
    with pytest.raises(ValueError, match="frames is an existing file"):
        server.start()


@pytest.mark.parametrize("options, message", [
    ({"host": "256.1.1.1"}, "not an IP address"),
    ({"host": "example.com"}, "not an IP address"),
    ({"port": 70000}, "not a TCP port"),
    ({"max_connections": 0}, "at least 1"),
    ({"idle_timeout_s": 0.0}, "idle timeout"),
    ({"idle_timeout_s": math.nan}, "idle timeout"),
    ({"image_folder_max_mb": -1.0}, "image folder cap"),
    ({"allowed_origins": ("http://a b",)}, "one word"),
])
def test_bad_settings_are_refused(options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        DriveServerConfig(**options)


def test_drive_refuses_a_bad_host_before_saying_it_listens(tmp_path: Path, capsys) -> None:
    assert main(["drive", str(tmp_path / "model.keras"), "--host", "256.1.1.1"]) == 2
    err = capsys.readouterr().err
    assert "256.1.1.1" in err and "not an IP address" in err and "listening" not in err
    assert err.count("\n") == 1


def test_drive_command_defaults_are_the_config_defaults() -> None:
    from clonedrive.cli import build_parser

    args = build_parser().parse_args(["drive", os.devnull])
    defaults = DriveServerConfig()
    assert (args.host, args.port, args.max_connections, args.idle_timeout,
            args.image_folder_max_mb) == (defaults.host, defaults.port, defaults.max_connections,
                                          defaults.idle_timeout_s, defaults.image_folder_max_mb)
