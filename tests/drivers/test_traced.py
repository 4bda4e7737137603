"""The traced forward pass: the same outputs as predict_on_batch to the last bit, or not used."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from clonedrive.drivers.network import NetworkPolicy
from clonedrive.drivers.traced import MAX_TRACES, TracedForward, forward_for
from clonedrive.model.architectures import MODEL_NAMES, build_model

FIXTURES = Path(__file__).parents[1] / "fixtures" / "udacity"


@pytest.fixture(scope="module")
def real_frames() -> np.ndarray:
    paths = sorted((FIXTURES / "lake_posix_mixed_columns" / "IMG").glob("center_*.jpg"))[:12]
    return np.stack([cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB) for path in paths])


@pytest.mark.parametrize("architecture", MODEL_NAMES)
@pytest.mark.parametrize("speed_head", [False, True])
def test_traced_outputs_equal_predict_on_batch_bit_for_bit(real_frames, architecture,
                                                           speed_head) -> None:
    model = build_model(architecture, seed=5, speed_head=speed_head)
    forward = forward_for(model)
    assert isinstance(forward, TracedForward)
    for batch in (real_frames[:8], real_frames[8:9], real_frames[:8][::-1]):
        got = forward(batch)  # first call of a size: predict_on_batch, then the checked trace
        want = model.predict_on_batch(batch)
        got, want = (got, want) if speed_head else ([got], [want])
        for a, b in zip(got, want, strict=True):
            np.testing.assert_array_equal(a, b)
    assert sorted(forward.traced_shapes) == [(1, 160, 320, 3), (8, 160, 320, 3)]
    # Through the policy: the same steering and learned speed as the model gives.
    policy = NetworkPolicy(model)
    for _ in range(2):
        steering, speed = policy.predict(real_frames)
        want = model.predict_on_batch(real_frames)
        want_steering = np.asarray(want[0] if speed_head else want)[:, 0]
        np.testing.assert_array_equal(steering, np.clip(want_steering, -1, 1))
        assert (speed is not None) == speed_head


def test_a_trace_that_differs_is_not_used(real_frames) -> None:
    """A layer whose output depends on Python state the trace would freeze: the trace's
    output differs from predict_on_batch's on the first batch, so it is never used."""
    import keras
    from keras import layers, ops

    class Calls(layers.Layer):
        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.calls = 0

        def call(self, x):
            self.calls += 1
            return ops.mean(x, axis=(1, 2, 3))[:, None] * 0.0 + float(self.calls)

    inputs = keras.Input((160, 320, 3), dtype="uint8")
    model = keras.Model(inputs, Calls()(ops.cast(inputs, "float32")))
    forward = forward_for(model)
    first = np.asarray(forward(real_frames[:2]))
    second = np.asarray(forward(real_frames[:2]))
    assert forward.traced_shapes == []
    assert first[0, 0] < second[0, 0]  # each call ran the layer's Python again


def test_traces_are_bounded_and_onnx_is_not_traced(real_frames) -> None:
    pytest.importorskip("onnxruntime")
    from clonedrive.drivers.onnx_runtime import OnnxModel, onnx_bytes

    model = build_model("fast", seed=1)
    forward = forward_for(model)
    frames = np.concatenate([real_frames] * 2)
    for size in range(1, MAX_TRACES + 5):
        np.testing.assert_array_equal(forward(frames[:size]),
                                      model.predict_on_batch(frames[:size]))
    assert len(forward.traced_shapes) == MAX_TRACES
    onnx_model = OnnxModel(onnx_bytes(model))
    assert forward_for(onnx_model) == onnx_model.predict_on_batch
    # A read-only frame (a view of a buffer) is copied, not refused.
    frozen = real_frames[:8].copy()
    frozen.flags.writeable = False
    np.testing.assert_array_equal(forward(frozen), model.predict_on_batch(real_frames[:8]))
