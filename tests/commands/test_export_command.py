"""``clonedrive export --onnx`` and the model options of ``evaluate``, through the CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clonedrive.cli import main
from clonedrive.model.architectures import build_model

pytest.importorskip("onnxruntime")


def test_export_onnx(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    build_model("fast", seed=0).save(tmp_path / "model.keras")
    assert main(["export", str(tmp_path / "model.keras"), "--onnx"]) == 0
    out = capsys.readouterr().out
    assert "outputs steering" in out and "max |ONNX Runtime - Keras|" in out
    difference = float(out.rsplit(":", 1)[1])
    assert difference <= 1e-4
    assert (tmp_path / "model.onnx").is_file()
    target = tmp_path / "sub" / "named.onnx"
    target.parent.mkdir()
    assert main(["export", str(tmp_path / "model.keras"), "--onnx", "--out", str(target)]) == 0
    assert target.is_file()


def test_export_and_evaluate_refuse_bad_models(tmp_path: Path,
                                               capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "model.keras"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 999, dtype=np.uint8).tobytes())
    assert main(["export", str(path), "--onnx"]) == 1
    assert main(["evaluate", str(path), "--runtime", "onnx", "--out", str(tmp_path / "e")]) == 2
    err = capsys.readouterr().err
    assert err.count("model.keras: not a Keras model file") == 2 and "Traceback" not in err
    assert not (tmp_path / "e").exists()
    assert main(["export", str(path), "--onnx", "--out", str(tmp_path / "x.bin")]) == 2
