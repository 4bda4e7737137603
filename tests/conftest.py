"""Shared test set-up: the project's default Keras backend before any test module imports keras,
SIGINT deliverable to the clonedrive processes the tests start, and the fixtures several test
files need (a free port, a recorded Udacity frame, tiny models)."""

from __future__ import annotations

import signal
import socket
from pathlib import Path

import pytest

from clonedrive.base.keras_backend import choose_backend

choose_backend()


def pytest_configure(config: pytest.Config) -> None:
    """A shell starts a background job (``pytest ... &``) with SIGINT ignored, and every child
    inherits that, so the tests that stop a real ``clonedrive`` process with SIGINT (Ctrl-C)
    would wait for it in vain. An exec resets a handled signal to its default, so handling it
    here gives the children Python's own Ctrl-C handling back."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)

FIXTURES = Path(__file__).resolve().parent / "fixtures"
#: Frames the Udacity simulator recorded (320x160 JPEGs, quality 75).
UDACITY_IMAGES = FIXTURES / "udacity" / "stationary" / "IMG"
#: The seed of the shared tiny model (its weights, not its driving, matter to the tests).
TINY_MODEL_SEED = 3


@pytest.fixture()
def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listened on a moment ago (connecting is refused)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture(scope="session")
def recorded_jpeg() -> bytes:
    """The bytes of a center-camera JPEG recorded by the Udacity simulator."""
    return sorted(UDACITY_IMAGES.glob("center_*.jpg"))[0].read_bytes()


@pytest.fixture(scope="session")
def tiny_model():
    """The tiny steering network (:mod:`clonedrive.network.tiny_model`), seeded; shared, so
    tests must not train or change it."""
    from clonedrive.network.tiny_model import build_tiny_model

    return build_tiny_model(seed=TINY_MODEL_SEED)


@pytest.fixture(scope="session")
def tiny_model_path(tiny_model, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """:func:`tiny_model` saved as ``tiny.keras`` (the format ``clonedrive drive`` loads)."""
    path = tmp_path_factory.mktemp("tiny_model") / "tiny.keras"
    tiny_model.save(path)
    return path


@pytest.fixture(scope="session")
def tiny_h5_path(tiny_model, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """:func:`tiny_model` saved as ``model.h5`` (the file format Udacity's drive.py loads)."""
    path = tmp_path_factory.mktemp("tiny_h5") / "model.h5"
    tiny_model.save(path)
    return path
