"""A ``clonedrive web`` app on 127.0.0.1 (any free port, a known token), and a headless
Chromium driven by Playwright (Debian's chromium; the tests skip, saying why, without it)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

CHROMIUM = "/usr/bin/chromium"
#: Without the background-networking flags Chromium's own connections get refused in CI
#: containers; no GPU and no sandbox there either.
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync"]
TOKEN = "test-token-0123456789"


@pytest.fixture(scope="module")
def web_app(tiny_model, tmp_path_factory):
    """The app on lake (no scenery: quick), the tiny model as its model; stepping once a page
    connects."""
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.web.app import WebApp, WebSession
    from clonedrive.web.config import WebConfig

    out = tmp_path_factory.mktemp("web") / "recording"
    config = WebConfig(port=0, token=TOKEN)
    setup = WebSession(track="lake", out_dir=str(out), scenery=False)
    policy = NetworkPolicy(tiny_model, set_speed_mph=9.0)
    with WebApp(config, setup, policy=policy, model_name="tiny") as app:
        yield app


@pytest.fixture(scope="module")
def browser():
    if not Path(CHROMIUM).is_file() and shutil.which("chromium") is None:
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install chromium)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="pip install playwright")
    with sync_api.sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS,
                                             headless=True)
        yield browser
        browser.close()
