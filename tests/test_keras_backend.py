"""Choosing the Keras backend: keras.json is respected only when it names an installed backend."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from clonedrive.base import keras_backend


def write_keras_json(folder: Path, backend: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "keras.json").write_text(json.dumps({"backend": backend}), encoding="utf-8")


@pytest.mark.skipif(importlib.util.find_spec("tensorflow") is not None,
                    reason="tensorflow is installed here")
def test_a_keras_json_naming_a_missing_backend_is_ignored(tmp_path, monkeypatch) -> None:
    # What the first `import keras` on a machine writes, whatever KERAS_BACKEND says.
    write_keras_json(tmp_path, "tensorflow")
    monkeypatch.setenv("KERAS_HOME", str(tmp_path))
    assert keras_backend._keras_json_backend() is None


def test_a_keras_json_naming_an_installed_backend_is_respected(tmp_path, monkeypatch) -> None:
    write_keras_json(tmp_path, "torch")
    monkeypatch.setenv("KERAS_HOME", str(tmp_path))
    assert keras_backend._keras_json_backend() == "torch"
    write_keras_json(tmp_path, "no-such-backend")
    assert keras_backend._keras_json_backend() is None


@pytest.mark.slow
def test_second_run_after_keras_wrote_its_json(tmp_path) -> None:
    """Two fresh processes with an empty KERAS_HOME: the first import writes keras.json, the
    second run must still get a working backend."""
    env = {key: value for key, value in os.environ.items()
           if key != "KERAS_BACKEND"}
    env["KERAS_HOME"] = str(tmp_path / "home")
    code = ("from clonedrive.base.keras_backend import import_keras; "
            "print(import_keras().backend.backend())")
    runs = [subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                           text=True, timeout=120) for _ in range(2)]
    assert (tmp_path / "home" / "keras.json").is_file()
    for run in runs:
        assert run.returncode == 0, run.stderr[-2000:]
        assert run.stdout.strip().splitlines()[-1] == keras_backend.DEFAULT_BACKEND


def test_compute_threads_sets_and_restores_pytorch_threads() -> None:
    import torch

    before = torch.get_num_threads()
    with keras_backend.compute_threads(1):
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == before
    with keras_backend.compute_threads(None):
        assert torch.get_num_threads() == before
    with pytest.raises(RuntimeError), keras_backend.compute_threads(1):
        raise RuntimeError("restored on the way out too")
    assert torch.get_num_threads() == before
