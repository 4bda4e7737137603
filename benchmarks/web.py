"""``clonedrive web`` as a person meets it: frames/s delivered to a real browser while recording,
and the key-press-to-changed-frame latency.

A headless Chromium (Debian's, through Playwright) opens the page. Phase 1: the expert drives
lake with the record toggle on for ``--seconds`` of wall-clock time; ``frames_per_s`` = frames
the page drew / wall seconds (target >= 15, the simulation's rate); ``frames_drawn_fraction``
= frames drawn / frames the server made meanwhile (1: none skipped); ``sim_realtime_ratio`` =
simulated / wall seconds (1: the session kept its 15 Hz). Phase 2, still recording,
manual mode: ``--presses`` times, a steering key goes down, then up; each key message's
latency is from the page's key handler to the page having drawn the first frame rendered after
the session applied that key (the frame reports the last input it applied), so it holds the
wait for the next 1/15 s step, the step, the JPEG, the socket and the browser's decode and
draw. ``latency_ms_median`` (target <= 150) and p90.

Run: python benchmarks/web.py [--seconds 20] [--presses 40] [--no-scenery] [--view three]
[--screenshot docs/images/web.png] (the page at the end of phase 1, as a 96-colour PNG)
Prints its figures, the 1-minute load average beside them (the CPU may be shared), and ends
with one JSON line.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync"]


def measure(args: argparse.Namespace) -> dict:
    from playwright.sync_api import sync_playwright

    from clonedrive.web.app import WebApp, WebSession
    from clonedrive.web.config import WebConfig

    out = tempfile.mkdtemp(prefix="web-bench-")
    config = WebConfig(port=0, view=args.view)
    setup = WebSession(track="lake", out_dir=os.path.join(out, "recording"),
                       scenery=not args.no_scenery)
    with WebApp(config, setup) as app, sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1000, "height": 820}, bypass_csp=True)
        page.goto(app.url)
        page.wait_for_function("window.clonedrive.frames > 5", timeout=120_000)
        page.keyboard.press("2")  # the expert drives
        page.keyboard.press("r")
        page.wait_for_function("window.clonedrive.state.recording", timeout=60_000)
        frames_0, wall_0 = page.evaluate("window.clonedrive.frames"), time.monotonic()
        sim_0 = page.evaluate("window.clonedrive.state.time_s")
        made_0 = page.evaluate("window.clonedrive.state.frame")
        time.sleep(args.seconds)
        frames_1, wall_1 = page.evaluate("window.clonedrive.frames"), time.monotonic()
        sim_1 = page.evaluate("window.clonedrive.state.time_s")
        made_1 = page.evaluate("window.clonedrive.state.frame")
        if args.screenshot:
            save_screenshot(page, args.screenshot)
        page.keyboard.press("1")  # manual: the keys steer
        page.evaluate("window.clonedrive.latencies = []")
        for _ in range(args.presses):
            page.keyboard.down("a")
            time.sleep(0.25)
            page.keyboard.up("a")
            time.sleep(0.25)
        time.sleep(0.5)
        latencies = page.evaluate("window.clonedrive.latencies")
        page.keyboard.press("r")
        page.wait_for_function("!window.clonedrive.state.recording", timeout=60_000)
        rows = page.evaluate("window.clonedrive.state.rows")
        browser.close()
    latencies.sort()
    return {
        "frames_per_s": round((frames_1 - frames_0) / (wall_1 - wall_0), 2),
        "frames_drawn_fraction": round((frames_1 - frames_0) / max(made_1 - made_0, 1), 3),
        "sim_realtime_ratio": round((sim_1 - sim_0) / (wall_1 - wall_0), 3),
        "latency_ms_median": round(statistics.median(latencies), 1),
        "latency_ms_p90": round(latencies[int(0.9 * (len(latencies) - 1))], 1),
        "latency_samples": len(latencies),
        "rows_recorded": rows,
        "view": args.view,
        "scenery": not args.no_scenery,
        "load_1min": round(os.getloadavg()[0], 2),
        "cpus": os.cpu_count(),
    }


def save_screenshot(page, path: str) -> None:
    """The page as a PNG of at most 96 colours (small enough to commit)."""
    import io

    from PIL import Image

    image = Image.open(io.BytesIO(page.screenshot(full_page=True))).convert("RGB")
    image.quantize(96).save(path, optimize=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="phase 1's wall time")
    parser.add_argument("--presses", type=int, default=40, help="phase 2's key presses")
    parser.add_argument("--view", choices=("center", "three"), default="center")
    parser.add_argument("--no-scenery", action="store_true")
    parser.add_argument("--screenshot", metavar="PNG", help="save the page there")
    args = parser.parse_args()
    load_before = round(os.getloadavg()[0], 2)
    figures = measure(args)
    figures["load_1min_before"] = load_before
    print(f"frames/s delivered while recording: {figures['frames_per_s']} (target >= 15); "
          f"simulated s per wall s {figures['sim_realtime_ratio']}; frames drawn / made "
          f"{figures['frames_drawn_fraction']}")
    print(f"key-press-to-frame latency: median {figures['latency_ms_median']} ms, p90 "
          f"{figures['latency_ms_p90']} ms over {figures['latency_samples']} key messages "
          "(target median <= 150)")
    print(f"rows recorded: {figures['rows_recorded']}; load average (1 min) "
          f"{load_before} before, {figures['load_1min']} after, {figures['cpus']} CPUs")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
