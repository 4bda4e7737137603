"""``clonedrive autonomous`` reads a server's ``steer`` reply as the Udacity simulator's
``float.Parse`` does: a reply Python's ``float()`` would take but the simulator would not
("1_0", "nan", "inf") is reported, one line naming it, never driven with (as 10.0)."""

from __future__ import annotations

import json
import threading

import pytest
from support.cli_process import refused, run_clonedrive
from websockets.exceptions import ConnectionClosed
from websockets.sync.server import serve

OPEN = '0{"sid":"s","upgrades":[],"pingTimeout":60000,"pingInterval":25000}'


class ReplyingServer:
    """A real WebSocket drive server on 127.0.0.1 answering every telemetry with ``reply``
    (the steering string), and counting the telemetry it saw."""

    def __init__(self, reply: str) -> None:
        self.reply = '42["steer",' + json.dumps({"steering_angle": reply,
                                                 "throttle": "0.2"}) + "]"
        self.telemetry = 0
        self._server = serve(self._handle, "127.0.0.1", 0)
        self.port = self._server.socket.getsockname()[1]
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)

    def _handle(self, connection) -> None:
        connection.send(OPEN)
        connection.send("40")
        try:
            for frame in connection:
                if frame.startswith('42["telemetry"'):
                    self.telemetry += 1
                    connection.send(self.reply)
                elif frame == "2":
                    connection.send("3")
        except ConnectionClosed:
            pass

    def __enter__(self) -> ReplyingServer:
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._server.shutdown()
        self._thread.join()


@pytest.mark.parametrize("reply", ["1_0", "nan", "inf", "0x1p-2"])
def test_autonomous_reports_a_reply_the_simulator_would_not_parse(reply: str) -> None:
    with ReplyingServer(reply) as server:
        result = run_clonedrive("autonomous", "--port", server.port, "--max-seconds", "1",
                                "--no-scenery", "--json")
    message = refused(result, "autonomous", 1)
    assert "steering_angle" in message and repr(reply) in message
    assert server.telemetry == 1  # stopped at the first such reply: nothing driven with it
    assert result.stdout == ""


def test_autonomous_drives_with_a_plain_reply() -> None:
    with ReplyingServer("-0.0125") as server:
        result = run_clonedrive("autonomous", "--port", server.port, "--max-seconds", "1",
                                "--no-scenery", "--json")
    assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads(result.stdout)
    assert summary["server_replies"] == summary["telemetry_sent"] == server.telemetry > 0
