"""``clonedrive web``: its help, its errors, and a real process printing its URL."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys
import urllib.error
import urllib.request

import pytest

from clonedrive.cli import main


def test_help_ends_with_example_command_lines(capsys):
    with pytest.raises(SystemExit):
        main(["web", "--help"])
    lines = capsys.readouterr().out.rstrip().splitlines()
    assert lines[-3] == "examples:"
    assert all(line.strip().startswith("clonedrive web ") for line in lines[-2:])


def test_a_busy_port_is_reported_before_the_model_loads(capsys, tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        code = main(["web", "--port", str(port), "--model", str(tmp_path / "missing.keras"),
                     "--out", str(tmp_path / "out")])
    error = capsys.readouterr().err
    assert code == 2
    assert error.startswith("clonedrive web: ") and f"--port {port + 1}" in error
    assert "missing.keras" not in error


@pytest.mark.parametrize("args, expected", [
    (["--track", "nowhere"], "nowhere"),
    (["--look", "purple"], "--look 'purple'"),
    (["--host", "my-laptop"], "not an IP address"),
    (["--port", "70000"], "not a TCP port"),
])
def test_bad_options_are_named(capsys, args, expected):
    assert main(["web", *args]) == 2
    error = capsys.readouterr().err
    assert error.startswith("clonedrive web: ") and expected in error


@pytest.mark.slow
def test_the_process_prints_its_url_with_a_token_and_warns_on_every_interface(tmp_path):
    process = subprocess.Popen(
        [sys.executable, "-m", "clonedrive", "web", "--host", "0.0.0.0", "--port", "0",
         "--no-scenery", "--out", str(tmp_path / "out")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = process.stdout.readline().strip()
        assert re.fullmatch(r"http://127\.0\.0\.1:\d+/\?token=[\w-]{20,}", url), url
        with urllib.request.urlopen(url, timeout=30) as response:
            assert response.status == 200
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(url.split("?")[0], timeout=30)
        assert refused.value.code == 403
    finally:
        process.send_signal(signal.SIGINT)
        _, error = process.communicate(timeout=60)
    assert process.returncode == 0, error
    assert "anyone on the network with the URL can drive" in error
