"""clonedrive: behavioural cloning of driving, end to end and headless."""

import os as _os

# Keras 3 runs on PyTorch here unless the user chose another backend.
_os.environ.setdefault("KERAS_BACKEND", "torch")

__version__ = "0.1.0"


def _register_gymnasium_envs() -> None:
    try:
        from clonedrive.envs import register_envs
    except ModuleNotFoundError:  # gymnasium missing: the rest of clonedrive still works
        return
    register_envs()


_register_gymnasium_envs()
