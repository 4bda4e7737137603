"""One drive server, several simulators, over real sockets on 127.0.0.1: each connection drives
with its own speed controller, steering filter and hold (two cars at once get, bit for bit, what
each gets alone), a client that stops reading is closed as idle, the server's own origin (what
websocket-client and python-socketio's client send) is accepted while a foreign one is refused,
and doubled Host or Origin headers get 400 without a traceback."""

from __future__ import annotations

import asyncio
import base64
import logging
import socket
import threading
import time

import pytest
import socketio
import websocket
from websockets.asyncio.client import connect

from clonedrive.drivers.policy import NetworkPolicy
from clonedrive.udacity import protocol
from clonedrive.udacity.server import DriveServer

TIMEOUT_S = 10.0
WAIT_S = 60.0  # the longest a test waits for the server to notice something (not a timing)


def frame(jpeg: bytes, speed_mph: float) -> str:
    image = base64.b64encode(jpeg).decode("ascii")
    return ('42["telemetry",{"steering_angle":"0.0000","throttle":"0.0000",'
            f'"speed":"{speed_mph:.4f}","image":"{image}"}}]')


def car_frames(recorded_jpeg: bytes) -> dict[str, list[str]]:
    """Two cars' telemetry: different images and speeds, so shared state would show."""
    image = protocol.decode_image(recorded_jpeg)
    mirrored = protocol.encode_image(image[:, ::-1].copy(), quality=95)
    darker = protocol.encode_image((image // 2).copy(), quality=95)
    return {
        "a": [frame(recorded_jpeg, speed) for speed in (0.0, 4.0, 8.5, 9.0, 12.0, 6.0)],
        "b": [frame(jpeg, speed) for jpeg, speed in
              zip([mirrored, darker] * 3, (20.0, 1.0, 0.0, 15.0, 3.0, 30.0), strict=True)],
    }


async def _open(port: int):
    ws = await connect(f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket",
                       compression=None, open_timeout=TIMEOUT_S)
    for _ in range(2):  # Engine.IO open, Socket.IO connect
        await asyncio.wait_for(ws.recv(), TIMEOUT_S)
    return ws


def drive(port: int, frames: dict[str, list[str]]) -> dict[str, list[str]]:
    """Connect one client per car, all at once; each step every car sends its frame before any
    reply is read. Returns each car's replies."""

    async def main():
        sockets = {car: await _open(port) for car in frames}
        replies: dict[str, list[str]] = {car: [] for car in frames}
        for step in range(len(next(iter(frames.values())))):
            for car, ws in sockets.items():
                await ws.send(frames[car][step])
            for car, ws in sockets.items():
                replies[car].append(await asyncio.wait_for(ws.recv(), TIMEOUT_S))
        for ws in sockets.values():
            await ws.close()
        return replies

    return asyncio.run(main())


def test_two_simulators_drive_as_each_alone(tiny_model, recorded_jpeg: bytes) -> None:
    def policy() -> NetworkPolicy:
        return NetworkPolicy(tiny_model, set_speed_mph=9.0, steering_filter_s=1.0,
                             steering_hold=0.002)

    frames = car_frames(recorded_jpeg)
    alone = {}
    for car in frames:
        with DriveServer(policy(), port=0, status_interval_s=0) as server:
            alone[car] = drive(server.port, {car: frames[car]})[car]
    with DriveServer(policy(), port=0, status_interval_s=0) as server:
        together = drive(server.port, frames)
        stats = server.stats()
    assert together == alone  # the reply strings, so bit-identical controls
    assert alone["a"] != alone["b"]
    assert (stats.connections, stats.steer, stats.safe) == (2, 12, 0)


def wait_until(condition) -> bool:
    end = time.monotonic() + WAIT_S
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.05)
    return False


def test_a_client_that_stops_reading_is_closed_as_idle() -> None:
    """Pings carry big payloads that the server echoes; the client reads none of its pongs, so
    the server's send buffer fills and a send waits: the idle timeout ends that wait."""

    class Still:
        def reset(self) -> None:
            pass

        def act(self, image_rgb, speed_mph):
            return 0.0, 0.0

    payload = "2" + "x" * 500_000

    async def flood(port: int) -> None:
        url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
        async with connect(url, compression=None, max_queue=1, max_size=None,
                           open_timeout=TIMEOUT_S, ping_interval=None) as ws:
            try:
                for _ in range(200):  # 100 MB: far more than any socket buffers
                    await asyncio.wait_for(ws.send(payload), WAIT_S)
            except Exception:  # noqa: BLE001 - the server closed or stopped reading: done
                pass

    with DriveServer(Still(), port=0, status_interval_s=0, idle_timeout_s=1.0) as server:
        thread = threading.Thread(target=asyncio.run, args=(flood(server.port),), daemon=True)
        thread.start()
        assert wait_until(lambda: server.stats().connections == 1)
        assert wait_until(lambda: server.stats().active_connections == 0)
        thread.join(WAIT_S)
        stats = server.stats()
    assert stats.idle_closed == 1
    assert stats.pings >= 1


def test_websocket_client_defaults_are_accepted(recorded_jpeg: bytes) -> None:
    with DriveServer(NetworkPolicyless(), port=0, status_interval_s=0) as server:
        ws = websocket.create_connection(
            f"ws://127.0.0.1:{server.port}/socket.io/?EIO=4&transport=websocket",
            timeout=TIMEOUT_S)  # sends Origin: http://127.0.0.1:PORT
        try:
            handshake = [ws.recv(), ws.recv()]
            ws.send(frame(recorded_jpeg, 3.0))
            reply = ws.recv()
        finally:
            ws.close()
        with pytest.raises(websocket.WebSocketBadStatusException) as refused:
            websocket.create_connection(
                f"ws://127.0.0.1:{server.port}/socket.io/?EIO=4&transport=websocket",
                timeout=TIMEOUT_S, origin="http://evil.example")
        with pytest.raises(websocket.WebSocketBadStatusException) as other_port:
            websocket.create_connection(
                f"ws://127.0.0.1:{server.port}/socket.io/?EIO=4&transport=websocket",
                timeout=TIMEOUT_S, origin=f"http://127.0.0.1:{server.port + 1}")
    assert handshake[1] == "40"
    assert reply == '42["steer",{"steering_angle":"0.125","throttle":"0.5"}]'
    assert refused.value.status_code == 403
    assert other_port.value.status_code == 403


class NetworkPolicyless:
    """Fixed controls, no per-car state (so the server shares it)."""

    def reset(self) -> None:
        pass

    def act(self, image_rgb, speed_mph):
        return 0.125, 0.5


def test_python_socketio_client_drives(recorded_jpeg: bytes) -> None:
    """python-socketio 4's client, as a student's script would use it (websocket transport)."""
    replies: list[dict] = []
    got = threading.Event()
    client = socketio.Client()

    @client.on("steer")
    def on_steer(data):
        replies.append(data)
        got.set()

    image = base64.b64encode(recorded_jpeg).decode("ascii")
    with DriveServer(NetworkPolicyless(), port=0, status_interval_s=0) as server:
        client.connect(f"http://127.0.0.1:{server.port}", transports=["websocket"])
        try:
            client.emit("telemetry", {"steering_angle": "0", "throttle": "0", "speed": "1",
                                      "image": image})
            assert got.wait(TIMEOUT_S)
        finally:
            _disconnect_after_the_write_thread(client)
    assert replies == [{"steering_angle": "0.125", "throttle": "0.5"}]


def _disconnect_after_the_write_thread(client: socketio.Client) -> None:
    """``client.disconnect()`` once the client's write thread has ended. python-engineio 3's
    disconnect queues a close packet for that thread and closes the socket at once, so the
    thread can send on a closed socket: an OSError in the thread, which pytest reports as a
    warning under a later test. An empty entry ends the thread first (what disconnect queues
    after its packet)."""
    client.eio.queue.put(None)
    client.eio.write_loop_task.join(TIMEOUT_S)
    client.disconnect()


def raw_upgrade_status(port: int, *headers: str) -> int:
    lines = ["GET /socket.io/?EIO=4&transport=websocket HTTP/1.1", *headers,
             "Upgrade: websocket", "Connection: Upgrade",
             "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==", "Sec-WebSocket-Version: 13"]
    with socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        status_line = sock.makefile("rb").readline().decode()
    return int(status_line.split()[1])


def test_doubled_host_or_origin_headers_get_400(caplog) -> None:
    with caplog.at_level(logging.DEBUG), \
            DriveServer(NetworkPolicyless(), port=0, status_interval_s=0) as server:
        host = f"Host: 127.0.0.1:{server.port}"
        own = f"Origin: http://127.0.0.1:{server.port}"
        statuses = [raw_upgrade_status(server.port, host, host),
                    raw_upgrade_status(server.port, host, own, own),
                    raw_upgrade_status(server.port, host, own)]
        stats = server.stats()
    assert statuses == [400, 400, 101]
    assert stats.refused == {"headers": 2}
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR or r.exc_info]
