"""Choosing the Keras backend, where Keras is first needed (never at ``import clonedrive``).

Keras 3 reads its backend from ``KERAS_BACKEND`` or from ``"backend"`` in ``keras.json``
(``$KERAS_HOME/keras.json``, by default ``~/.keras/keras.json``). When the user set neither,
clonedrive picks PyTorch (:data:`DEFAULT_BACKEND`), the fastest backend on these machines;
whatever the user chose is respected.
"""

from __future__ import annotations

import json
import os
import sys
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
    return backend if isinstance(backend, str) else None


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
