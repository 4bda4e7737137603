"""``clonedrive web`` put together: a session, its controller and the page's server.

:class:`WebApp` opens them in order -- the server first, so that a busy port fails at once,
before a model or a track loads -- and steps the session on a thread of its own (or on the
caller's, :meth:`WebApp.serve_forever`).
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass

from clonedrive.web.config import DEFAULT_OUT_DIR, WebConfig


@dataclass(frozen=True)
class WebSession:
    """What ``clonedrive web`` drives: track, direction, look, pilots, recording folder."""

    track: str = "lake"
    reverse: bool = False
    look: str = "clear"
    out_dir: str = DEFAULT_OUT_DIR
    scenery: bool = True
    seed: int = 0
    image_width: int | None = None  #: camera image size (None: the Udacity 320x160)
    image_height: int | None = None


def check_port(host: str, port: int) -> None:
    """Raise OSError, saying what to do, when ``host:port`` cannot be listened on."""
    import errno
    import socket

    try:
        with socket.create_server((host, port)):
            return
    except OSError as error:
        if error.errno == errno.EADDRINUSE:
            raise OSError(error.errno, f"port {port} on {host} is already in use (another "
                          "clonedrive web?); choose another with --port, e.g. --port "
                          f"{port + 1}") from None
        raise OSError(error.errno, f"cannot listen on {host}:{port}: "
                      f"{error.strerror or error}") from None


class WebApp:
    """The server listening, then the session on ``setup.track`` (``policy``: the model the
    model modes use). Use as a context manager, or :meth:`open` / :meth:`close`."""

    def __init__(self, config: WebConfig, setup: WebSession, *, policy=None,
                 model_name: str = "model", manual_config=None) -> None:
        self.config = config
        self.setup = setup
        self.policy = policy
        self.model_name = model_name
        self.manual_config = manual_config
        self.controller = None
        self.server = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._ran = False

    def open(self) -> WebApp:
        """Listen (OSError when the port is taken) and open the session's track."""
        from dataclasses import replace

        from clonedrive.manual.config import ManualConfig
        from clonedrive.manual.session import DrivingSession
        from clonedrive.sim.simulator import SimConfig
        from clonedrive.web.controller import Controller
        from clonedrive.web.server import WebServer

        setup = self.setup
        manual = self.manual_config or ManualConfig(scenery=setup.scenery, seed=setup.seed)
        sim_config = SimConfig(scenery=setup.scenery)
        if setup.image_width is not None:
            sim_config = replace(sim_config, image_width=setup.image_width,
                                 image_height=setup.image_height)
        session = DrivingSession(manual, os.fspath(setup.out_dir), sim_config=sim_config)
        self.controller = Controller(session, self.config, track=setup.track,
                                     reverse=setup.reverse, look=setup.look,
                                     policy=self.policy, model_name=self.model_name)
        self.server = WebServer(self.controller, self.config)
        self.server.start()
        return self

    @property
    def url(self) -> str:
        return self.server.url

    def serve_forever(self) -> None:
        """Step the session on this thread until :meth:`close` (or Ctrl-C)."""
        self._ran = True
        self.controller.run(self.server.publish, self._stop, lambda: self.server.watched)

    def start(self) -> WebApp:
        """Step the session on a thread of its own."""
        self._thread = threading.Thread(target=self.serve_forever, name="web-session",
                                        daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop stepping (a recording is finished and its lock released), then serving."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(30.0)
            self._thread = None
        if self.controller is not None and not self._ran:
            self.controller.session.close()
        if self.server is not None:
            self.server.stop()

    def __enter__(self) -> WebApp:
        return self.open().start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()
