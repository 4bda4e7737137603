"""ONNX export and ONNX Runtime: parity with Keras on real Udacity frames (max |diff| <= 1e-4),
and the ONNX model driving through NetworkPolicy like the Keras one."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from clonedrive.drivers.policy import NetworkPolicy, load_policy  # noqa: E402
from clonedrive.model.architectures import MODEL_NAMES, build_model  # noqa: E402
from clonedrive.network.model_file import load_model  # noqa: E402
from clonedrive.network.onnx_runtime import OnnxModel, export_onnx, onnx_bytes  # noqa: E402

FIXTURES = Path(__file__).parents[1] / "fixtures" / "udacity"
PARITY_ABS = 1e-4


@pytest.fixture(scope="module")
def real_frames() -> np.ndarray:
    """Real Udacity centre frames from both tracks' fixture logs, RGB uint8."""
    paths = []
    for log in ("lake_posix_mixed_columns", "mountain_windows_paths"):
        paths += sorted((FIXTURES / log / "IMG").glob("center_*.jpg"))[::10]
    return np.stack([cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB) for path in paths])


@pytest.mark.parametrize("architecture", MODEL_NAMES)
def test_onnx_runtime_matches_keras_on_real_frames(tmp_path: Path, real_frames,
                                                    architecture: str) -> None:
    model = build_model(architecture, seed=3)
    path = export_onnx(model, tmp_path / f"{architecture}.onnx")
    onnx_model = load_model(path)
    assert isinstance(onnx_model, OnnxModel)
    assert onnx_model.output_names == ["steering"]
    assert onnx_model.inputs[0].shape == (None, 160, 320, 3)
    keras_out = np.asarray(model.predict_on_batch(real_frames.astype(np.float32)))
    onnx_out = np.asarray(onnx_model.predict_on_batch(real_frames))
    assert onnx_out.shape == keras_out.shape == (len(real_frames), 1)
    assert float(np.max(np.abs(onnx_out - keras_out))) <= PARITY_ABS
    # the same through the policy, several frames and one
    keras_policy, onnx_policy = NetworkPolicy(model), NetworkPolicy(onnx_model)
    np.testing.assert_allclose(onnx_policy.predict_steering(real_frames),
                               keras_policy.predict_steering(real_frames), atol=PARITY_ABS)
    assert onnx_policy.act(real_frames[0], 5.0) == pytest.approx(
        keras_policy.act(real_frames[0], 5.0), abs=PARITY_ABS)


def test_the_policy_hands_each_model_its_own_input_dtype(real_frames) -> None:
    """Our networks take uint8 frames, in Keras and ONNX alike, so the policy passes them as
    they are (no float copy for ONNX Runtime to round back); a float32-input model (a Udacity
    user's own) gets float32. The steering is the same either way."""
    import keras

    model = build_model("fast", seed=2)
    onnx_policy = NetworkPolicy(OnnxModel(onnx_bytes(model)))
    assert NetworkPolicy(model).input_dtype == onnx_policy.input_dtype == np.uint8
    inputs = keras.Input((160, 320, 3), dtype="float32")
    float_model = keras.Model(inputs, model(inputs))
    float_policy = NetworkPolicy(float_model)
    assert float_policy.input_dtype == np.float32
    np.testing.assert_array_equal(float_policy.predict_steering(real_frames),
                                  NetworkPolicy(model).predict_steering(real_frames))
    np.testing.assert_allclose(onnx_policy.predict_steering(real_frames),
                               float_policy.predict_steering(real_frames), atol=PARITY_ABS)


def test_runtime_onnx_converts_a_keras_file(tmp_path: Path, real_frames) -> None:
    model = build_model("fast", seed=1)
    model.save(tmp_path / "model.keras")
    policy = load_policy(tmp_path / "model.keras", runtime="onnx", set_speed_mph=12.0)
    assert isinstance(policy.model, OnnxModel) and policy.set_speed_mph == 12.0
    np.testing.assert_allclose(policy.predict_steering(real_frames),
                               np.asarray(model.predict_on_batch(
                                   real_frames.astype(np.float32)))[:, 0], atol=PARITY_ABS)
    assert list(tmp_path.iterdir()) == [tmp_path / "model.keras"]  # nothing written beside it


def test_two_output_model_keeps_its_output_names(tmp_path: Path) -> None:
    import keras
    from keras import layers

    inputs = keras.Input(shape=(160, 320, 3))
    pooled = layers.GlobalAveragePooling2D()(inputs)
    model = keras.Model(inputs, [layers.Dense(1, name="steering")(pooled),
                                 layers.Dense(1, name="target_speed")(pooled)])
    onnx_model = load_model(export_onnx(model, tmp_path / "two.onnx"))
    assert onnx_model.output_names == ["steering", "target_speed"]
    frames = np.random.default_rng(0).integers(0, 256, (3, 160, 320, 3), dtype=np.uint8)
    for got, want in zip(onnx_model.predict_on_batch(frames),
                         model.predict_on_batch(frames.astype(np.float32)), strict=True):
        np.testing.assert_allclose(got, want, atol=PARITY_ABS)


def test_bad_onnx_files(tmp_path: Path) -> None:
    (tmp_path / "model.onnx").write_bytes(b"\x08\x07garbage" * 20)
    with pytest.raises(ValueError, match="model.onnx: not an ONNX model"):
        load_model(tmp_path / "model.onnx")
    with pytest.raises(ValueError, match="runs with --runtime onnx"):
        load_model(tmp_path / "model.onnx", runtime="keras")
