"""Choosing the Keras backend, where Keras is first needed (never at ``import clonedrive``).

Keras 3 reads its backend from ``KERAS_BACKEND`` or from ``"backend"`` in ``keras.json``
(``$KERAS_HOME/keras.json``, by default ``~/.keras/keras.json``). When the user set neither,
clonedrive picks PyTorch (:data:`DEFAULT_BACKEND`), the fastest backend on these machines;
whatever the user chose is respected.

A ``keras.json`` naming a backend that is not installed is not a choice: the first ``import
keras`` on a machine writes ``keras.json`` with ``"backend": "tensorflow"`` even when
``KERAS_BACKEND`` says otherwise, so after one run every later one would fail with "No module
named 'tensorflow'". Such a file is ignored.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

DEFAULT_BACKEND = "torch"


def _keras_json_backend() -> str | None:
    home = Path(os.environ.get("KERAS_HOME", Path.home() / ".keras"))
    try:
        with open(home / "keras.json", encoding="utf-8") as handle:
            config = json.load(handle)
    except (OSError, ValueError):
        return None
    backend = config.get("backend") if isinstance(config, dict) else None
    if not isinstance(backend, str) or not _installed(backend):
        return None
    return backend


def _installed(backend: str) -> bool:
    """Whether the package behind a Keras backend name can be imported."""
    package = {"tensorflow": "tensorflow", "jax": "jax", "torch": "torch", "numpy": "numpy",
               "openvino": "openvino"}.get(backend)
    return package is not None and importlib.util.find_spec(package) is not None


def choose_backend() -> str:
    """The backend Keras will use; sets ``KERAS_BACKEND`` to the default only when the user
    chose none and Keras is not imported yet."""
    if "KERAS_BACKEND" in os.environ:
        return os.environ["KERAS_BACKEND"]
    chosen = _keras_json_backend()
    if chosen is not None:
        return chosen
    if "keras" in sys.modules:  # already imported by someone else: it has decided
        return sys.modules["keras"].backend.backend()
    os.environ["KERAS_BACKEND"] = DEFAULT_BACKEND
    return DEFAULT_BACKEND


def import_keras() -> ModuleType:
    """``keras``, with the backend chosen by :func:`choose_backend`."""
    choose_backend()
    import keras

    return keras


@contextlib.contextmanager
def compute_threads(threads: int | None) -> Iterator[None]:
    """PyTorch's intra-op threads set to ``threads`` inside the block and restored after it.

    ``None``, or PyTorch not loaded: nothing changes. (Running with fewer threads than cores
    leaves a core to work beside the network, such as a video encoder: PyTorch's threads wait
    on each other, so one that shares its core with another process slows them all.)
    """
    torch = sys.modules.get("torch")
    if threads is None or torch is None:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(max(1, int(threads)))
    try:
        yield
    finally:
        torch.set_num_threads(before)
