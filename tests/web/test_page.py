"""The page in a real headless browser: it shows the car, the keys drive it, the record toggle
writes a recording ``clonedrive check`` reads, and a takeover is counted."""

from __future__ import annotations

import json

import pytest

from tests.web.conftest import TOKEN

WAIT_MS = 60_000  # generous: the CI machine is shared; nothing here asserts a time


@pytest.fixture(scope="module")
def page(web_app, browser):
    # bypass_csp: Playwright evaluates its waiting conditions as strings, which the page's
    # Content-Security-Policy forbids (no eval)
    page = browser.new_page(viewport={"width": 1000, "height": 820}, bypass_csp=True)
    page.goto(f"http://127.0.0.1:{web_app.server.port}/?token={TOKEN}")
    page.wait_for_function("window.clonedrive.frames > 2", timeout=WAIT_MS)
    yield page
    page.close()


def state(page) -> dict:
    return page.evaluate("window.clonedrive.state")


def wait_until(page, condition: str) -> None:
    """Wait until ``condition`` (JavaScript over ``s``, the latest state) holds."""
    script = f"(() => {{ const s = window.clonedrive.state; return {condition}; }})()"
    page.wait_for_function(script, timeout=WAIT_MS)


def after_frames(page, count: int) -> None:
    frames = page.evaluate("window.clonedrive.frames")
    page.wait_for_function(f"window.clonedrive.frames >= {frames + count}", timeout=WAIT_MS)


def picture(page) -> str:
    return page.evaluate("document.getElementById('view').toDataURL('image/png')")


def test_the_page_shows_the_track_and_its_hud(page):
    s = state(page)
    assert s["track"] == "lake" and s["mode"] == "manual" and not s["recording"]
    assert s["time_s"] > 0 and s["speed_mph"] == 0.0  # parked: no -0.1 mph
    assert s["lap_time_s"] == 0.0  # the lap's clock waits for the car to move
    assert "lake" in page.inner_text("#status") and "mph" in page.inner_text("#status")
    assert page.evaluate("window.clonedrive.hello.tracks")[:2] == ["lake", "mountain"]


def test_holding_the_throttle_key_speeds_the_car_up_and_the_frame_changes(page):
    before_speed, before_picture = state(page)["speed_mph"], picture(page)
    page.keyboard.down("w")
    wait_until(page, f"s.speed_mph > {before_speed} + 1")
    page.keyboard.up("w")
    assert picture(page) != before_picture
    assert state(page)["throttle"] >= 0.0


def test_a_steering_key_turns_the_wheel_and_letting_go_centres_it(page):
    page.keyboard.down("ArrowLeft")
    wait_until(page, "s.steering < -0.2")
    page.keyboard.up("ArrowLeft")
    wait_until(page, "s.steering === 0")


def test_recording_two_seconds_writes_a_log_clonedrive_check_reads(page, web_app, capsys):
    from clonedrive.cli import main

    page.keyboard.down("w")
    page.keyboard.press("r")
    wait_until(page, "s.recording")
    start_s = state(page)["time_s"]
    wait_until(page, f"s.time_s >= {start_s} + 2")  # two seconds of simulated time
    page.keyboard.press("r")
    wait_until(page, "!s.recording")
    page.keyboard.up("w")
    rows = state(page)["rows"]
    assert rows >= 30  # 15 rows a second
    out = web_app.setup.out_dir
    capsys.readouterr()
    assert main(["check", out, "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["rows"] == rows and report["usable_rows"] == rows, report
    assert report["images_missing"] == report["images_corrupt"] == 0
    config = json.loads((web_app.controller.session.out_dir / "config.json").read_text())
    assert config["sessions"][-1]["rows"] == rows


def test_a_takeover_is_counted_and_letting_go_hands_back(page):
    page.keyboard.press("4")
    wait_until(page, "s.mode === 'takeover'")
    assert "tiny" in state(page)["hud_mode"]
    page.keyboard.down("d")
    wait_until(page, "s.taking_over && s.takeovers === 1")
    page.keyboard.up("d")
    wait_until(page, "!s.taking_over")
    assert state(page)["takeovers"] == 1
    page.keyboard.press("1")
    wait_until(page, "s.mode === 'manual'")


def test_p_hands_the_car_to_the_model_and_back_as_in_the_window(page):
    page.keyboard.press("p")
    wait_until(page, "s.mode === 'model'")
    page.keyboard.press("p")
    wait_until(page, "s.mode === 'manual'")
    legend = page.inner_text("#help")
    assert "P: the model drives" in legend and "M: mouse steering" in legend


def test_a_foreign_page_cannot_open_the_socket(page, web_app, browser):
    """Another site's page (another port of this machine), in the same browser, knowing the
    token even: the server refuses its upgrade."""
    import threading
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    class Blank(BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 (http.server's name)
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.end_headers()
            self.wfile.write(b"<!doctype html><title>another site</title>")

        def log_message(self, *args) -> None:
            """Quiet."""

    refused = web_app.server.refused.get("origin", 0)
    with ThreadingHTTPServer(("127.0.0.1", 0), Blank) as other_site:
        threading.Thread(target=other_site.serve_forever, daemon=True).start()
        other = browser.new_page()
        try:
            other.goto(f"http://127.0.0.1:{other_site.server_address[1]}/")
            opened = other.evaluate(
                """([port, token]) => new Promise(done => {
                     const ws = new WebSocket(`ws://127.0.0.1:${port}/ws?token=${token}`);
                     ws.onopen = () => done(true);
                     ws.onerror = () => done(false);
                   })""", [web_app.server.port, TOKEN])
        finally:
            other.close()
            other_site.shutdown()
    assert opened is False
    assert web_app.server.refused.get("origin", 0) == refused + 1
