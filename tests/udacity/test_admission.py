"""Which upgrades the drive server accepts, read from the rules themselves (no socket)."""

from __future__ import annotations

import pytest
from websockets.datastructures import Headers
from websockets.http11 import Request

from clonedrive.udacity.admission import refusal
from clonedrive.udacity.server_config import DriveServerConfig

GOOD_PATH = "/socket.io/?EIO=4&transport=websocket"
PORT = 4567


def request(path: str = GOOD_PATH, **headers: str | list[str]) -> Request:
    pairs = []
    for name, values in headers.items():
        for value in values if isinstance(values, list) else [values]:
            pairs.append((name, value))
    return Request(path, Headers(pairs))


def test_the_simulator_s_upgrade_is_accepted() -> None:
    assert refusal(request(Host=f"127.0.0.1:{PORT}"), DriveServerConfig(), PORT, 0) is None
    own_origin = request(Host=f"127.0.0.1:{PORT}", Origin=f"http://127.0.0.1:{PORT}")
    assert refusal(own_origin, DriveServerConfig(), PORT, 0) is None


@pytest.mark.parametrize(("upgrade", "status", "reason"), [
    (request(Host=["127.0.0.1", "127.0.0.1"]), 400, "headers"),
    (request(Origin="https://example.com"), 403, "origin"),
    (request(Host="evil.example.com"), 403, "host"),
    (request("/other"), 404, None),
    (request("/socket.io/?EIO=2&transport=websocket"), 400, None),
    (request("/socket.io/?EIO=4&transport=polling"), 400, None),
])
def test_refusals_name_their_status_and_counted_reason(upgrade, status, reason) -> None:
    refused = refusal(upgrade, DriveServerConfig(), PORT, 0)
    assert (refused.status, refused.reason) == (status, reason)
    assert refused.detail and "\n" not in refused.detail


def test_a_full_server_refuses_with_503_and_says_idle_ones_close() -> None:
    config = DriveServerConfig(max_connections=2, idle_timeout_s=7.0)
    assert refusal(request(), config, PORT, 1) is None
    refused = refusal(request(), config, PORT, 2)
    assert (refused.status, refused.reason) == (503, "busy") and "7 s" in refused.detail
