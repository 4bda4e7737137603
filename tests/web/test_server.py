"""The server over real sockets on 127.0.0.1: token, Host and Origin refusals, and garbage on
the socket answered without harm."""

from __future__ import annotations

import asyncio
import http.client
import json

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from tests.web.conftest import TOKEN


def get(port: int, path: str, host: str | None = None) -> tuple[int, str, dict]:
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        connection.putrequest("GET", path, skip_host=host is not None)
        if host is not None:
            connection.putheader("Host", host)
        connection.endheaders()
        response = connection.getresponse()
        return response.status, response.read().decode(), dict(response.getheaders())
    finally:
        connection.close()


def socket_status(port: int, *, token: str = TOKEN, origin: str | None = None,
                  host: str | None = None) -> int:
    """101 if the upgrade is accepted, else the refusal's HTTP status."""
    async def attempt() -> int:
        # The URL names the Host header; host= and port= say where to connect.
        try:
            async with connect(f"ws://{host or f'127.0.0.1:{port}'}/ws?token={token}",
                               host="127.0.0.1", port=port, origin=origin, open_timeout=10):
                return 101
        except InvalidStatus as error:
            return error.response.status_code

    return asyncio.run(attempt())


def test_the_page_needs_its_token(web_app):
    port = web_app.server.port
    status, body, _ = get(port, "/")
    assert status == 403 and "token" in body
    assert get(port, "/?token=wrong-token-123")[0] == 403
    status, body, headers = get(port, f"/?token={TOKEN}")
    assert status == 200 and "<canvas" in body
    assert "frame-ancestors 'none'" in headers["Content-Security-Policy"]
    assert headers["Referrer-Policy"] == "no-referrer"
    assert get(port, f"/other?token={TOKEN}")[0] == 404


def test_a_host_header_that_is_not_this_server_is_refused(web_app):
    port = web_app.server.port
    assert get(port, f"/?token={TOKEN}", host=f"localhost:{port}")[0] == 200
    status, body, _ = get(port, f"/?token={TOKEN}", host=f"attacker.example:{port}")
    assert status == 403 and "Host" in body
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    connection.putrequest("GET", f"/?token={TOKEN}")  # a Host header of its own, and ...
    connection.putheader("Host", "attacker.example")  # ... a second one
    connection.endheaders()
    assert connection.getresponse().status == 403
    connection.close()
    assert socket_status(port, host=f"attacker.example:{port}",
                         origin=f"http://attacker.example:{port}") == 403


def test_the_socket_needs_the_token_and_its_own_pages_origin(web_app):
    port = web_app.server.port
    assert socket_status(port, token="wrong-token-123") == 403
    assert socket_status(port, origin="http://evil.example") == 403
    assert socket_status(port, origin=f"http://127.0.0.1:{port + 1}") == 403
    assert socket_status(port, origin=f"http://127.0.0.1:{port}") == 101
    assert socket_status(port) == 101  # no Origin: not a browser, and it has the token
    assert web_app.server.refused["origin"] >= 2 and web_app.server.refused["token"] >= 1


@pytest.mark.parametrize("message, expected", [
    ("not json", "not JSON"),
    ("[1, 2]", "JSON object"),
    ('{"type": "fly"}', "unknown type"),
    ('{"type": "key", "key": "escape", "down": true}', "not a driving key"),
    ('{"type": "key", "key": "w", "down": "yes"}', "down must be true or false"),
    ('{"type": "pointer", "x": "left"}', "pointer"),
    ('{"type": "axis", "axis": "left_x", "value": 1e999}', "axis"),
    ('{"type": "mode", "mode": "warp"}', "mode must be one of"),
    ('{"type": "record", "on": true, "rm": "-rf"}', "unknown field"),
    ('{"type": "reset", "seq": -1}', "seq"),
    (b"\x00\xff binary", "binary"),
])
def test_garbage_is_answered_with_an_error_and_the_connection_kept(web_app, message, expected):
    async def exchange() -> str:
        async with connect(f"ws://127.0.0.1:{web_app.server.port}/ws?token={TOKEN}") as ws:
            assert json.loads(await ws.recv())["type"] == "hello"
            await ws.send(message)
            while True:  # frames may arrive first
                reply = await asyncio.wait_for(ws.recv(), 30)
                if isinstance(reply, str):
                    break
            await ws.send('{"type": "view", "view": "center"}')  # still connected
            return json.loads(reply)["message"]

    assert expected in asyncio.run(exchange())


def test_an_oversized_message_closes_only_that_connection(web_app):
    async def oversized() -> int:
        async with connect(f"ws://127.0.0.1:{web_app.server.port}/ws?token={TOKEN}",
                           max_size=None) as ws:
            await ws.send("x" * (web_app.config.max_message_bytes + 1))
            try:
                while True:
                    await asyncio.wait_for(ws.recv(), 30)
            except ConnectionClosed as closed:
                return closed.rcvd.code

    assert asyncio.run(oversized()) == 1009
    assert socket_status(web_app.server.port) == 101  # the server keeps serving


def test_a_track_that_fails_to_load_leaves_the_car_where_it_was(web_app):
    async def choose_bad_track() -> dict:
        async with connect(f"ws://127.0.0.1:{web_app.server.port}/ws?token={TOKEN}") as ws:
            await ws.send('{"type": "track", "track": "gen:not-a-seed"}')
            while True:
                message = await asyncio.wait_for(ws.recv(), 60)
                if isinstance(message, bytes):
                    length = int.from_bytes(message[:4], "big")
                    state = json.loads(message[4:4 + length])
                    if "cannot load track" in state["message"]:
                        return state

    state = asyncio.run(choose_bad_track())
    assert state["track"] == "lake" and "gen:not-a-seed" in state["message"]


def test_bytes_that_are_not_http_are_dropped_and_the_server_keeps_serving(web_app):
    import socket

    port = web_app.server.port
    with socket.create_connection(("127.0.0.1", port), timeout=10) as raw:
        raw.sendall(b"\x16\x03\x01\x02\x00 not HTTP at all\r\n\r\n" + bytes(range(256)))
        raw.shutdown(socket.SHUT_WR)
        while raw.recv(4096):  # whatever it answers, it closes the connection
            pass
    assert get(port, f"/?token={TOKEN}")[0] == 200


def test_the_look_and_view_pickers_reopen_the_track_and_widen_the_picture(web_app):
    import cv2
    import numpy as np

    async def pick() -> tuple[dict, np.ndarray]:
        async with connect(f"ws://127.0.0.1:{web_app.server.port}/ws?token={TOKEN}") as ws:
            await ws.send('{"type": "look", "look": "udacity"}')
            await ws.send('{"type": "view", "view": "three"}')
            while True:
                message = await asyncio.wait_for(ws.recv(), 60)
                if isinstance(message, bytes):
                    length = int.from_bytes(message[:4], "big")
                    state = json.loads(message[4:4 + length])
                    if state["look"] == "udacity" and state["view"] == "three":
                        await ws.send('{"type": "view", "view": "center"}')
                        jpeg = np.frombuffer(message[4 + length:], np.uint8)
                        return state, cv2.imdecode(jpeg, cv2.IMREAD_COLOR)

    state, picture = asyncio.run(pick())
    assert state["track"] == "lake"
    assert picture.shape == (160, 3 * 320, 3)
