"""The traced forward pass: the same outputs as predict_on_batch to the last bit, or not used."""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np
import pytest

from clonedrive.drivers.policy import NetworkPolicy
from clonedrive.model.architectures import MODEL_NAMES, build_model
from clonedrive.network.traced import MAX_TRACES, TracedForward, forward_for

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
    # Through the policy: the same steering and learned speed as the model gives each frame.
    policy = NetworkPolicy(model)
    for _ in range(2):
        steering, speed = policy.predict(real_frames)
        want = [model.predict_on_batch(frame[None]) for frame in real_frames]
        want_steering = np.concatenate([np.asarray(one[0] if speed_head else one)[:, 0]
                                        for one in want])
        np.testing.assert_array_equal(steering, np.clip(want_steering, -1, 1))
        assert (speed is not None) == speed_head


def untraceable_model():
    """A model with a layer whose output depends on Python state a trace would freeze."""
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
    return model


def test_a_trace_that_differs_is_not_used(real_frames) -> None:
    """A layer whose output depends on Python state the trace would freeze: the trace's
    output differs from predict_on_batch's on the first batch, so it is never used."""
    model = untraceable_model()
    forward = forward_for(model)
    first = np.asarray(forward(real_frames[:2]))
    second = np.asarray(forward(real_frames[:2]))
    assert forward.traced_shapes == []
    assert first[0, 0] < second[0, 0]  # each call ran the layer's Python again


def dict_output_model():
    """A model whose output is a dict, which torch.jit.trace refuses (RuntimeError)."""
    import keras
    from keras import layers

    inputs = keras.Input((8, 8, 3))
    flat = layers.Flatten()(inputs)
    return keras.Model(inputs, {"steering": layers.Dense(1)(flat), "speed": layers.Dense(1)(flat)})


def backward_hook_model():
    """A model with a backward hook, which torch.jit.trace refuses (ValueError)."""
    import keras
    from keras import layers

    inputs = keras.Input((8, 8, 3))
    model = keras.Model(inputs, layers.Dense(1)(layers.Flatten()(inputs)))
    model.register_full_backward_hook(lambda *args: None)
    return model


@pytest.mark.parametrize(("build", "error"), [(dict_output_model, "RuntimeError"),
                                              (backward_hook_model, "ValueError")])
def test_a_model_torch_cannot_trace_predicts_and_says_why(build, error, caplog) -> None:
    model = build()
    images = np.random.default_rng(0).random((2, 8, 8, 3), dtype=np.float32)
    forward = forward_for(model)
    with caplog.at_level(logging.INFO, logger="clonedrive.model"):
        first, second = forward(images), forward(images[:1])
    assert forward.traced_shapes == []
    want = model.predict_on_batch(images)
    if isinstance(want, dict):
        assert sorted(first) == sorted(want)
        for name in want:
            np.testing.assert_array_equal(first[name], want[name])
    else:
        np.testing.assert_array_equal(first, want)
    assert len(second if not isinstance(second, dict) else second["speed"]) == 1
    infos = [record for record in caplog.records if record.levelno == logging.INFO]
    assert len(infos) == 1  # once per model, not once per batch size
    message = infos[0].getMessage()
    assert "predict_on_batch" in message and "cannot trace" in message and error in message


@pytest.mark.slow
def test_traces_are_bounded_and_onnx_is_not_traced(real_frames) -> None:
    pytest.importorskip("onnxruntime")
    from clonedrive.network.onnx_runtime import OnnxModel, onnx_bytes

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


def test_a_portable_model_drives_in_a_process_without_keras_to_the_last_bit(real_frames,
                                                                             tmp_path) -> None:
    """What evaluate hands its worker processes: the policy's checked trace of the one batch it
    predicts (a frame and its mirror image: 2 frames). A fresh process runs it with PyTorch
    alone, and steers and sets its speed exactly as the Keras model does."""
    import pickle
    import subprocess
    import sys

    from clonedrive.network.traced import TracedModel

    model = build_model("fast", seed=5, speed_head=True)
    policy = NetworkPolicy(model, mirror_average=True)
    portable = policy.portable()
    assert sorted(portable.traces) == [2]
    assert portable.output_names == tuple(model.output_names)
    frames = real_frames[:3]
    from clonedrive.base.keras_backend import compute_threads

    # One compute thread on both sides, as evaluate's and bench's workers run: the last bits of
    # a convolution depend on how many threads share it (another test may have changed this
    # process's count).
    with compute_threads(1):
        want = [policy.predict(frames[:count]) for count in (1, 2, 3)]
    (tmp_path / "portable.pkl").write_bytes(pickle.dumps((portable, frames)))
    script = (
        "import pickle, sys\n"
        "import torch\n"
        "torch.set_num_threads(1)\n"
        "from clonedrive.drivers.policy import NetworkPolicy\n"
        "from clonedrive.network.traced import TracedModel\n"
        f"portable, frames = pickle.loads(open({str(tmp_path / 'portable.pkl')!r}, 'rb').read())\n"
        "policy = NetworkPolicy(TracedModel(portable), mirror_average=True)\n"
        "got = [policy.predict(frames[:count]) for count in (1, 2, 3)]\n"
        f"open({str(tmp_path / 'got.pkl')!r}, 'wb').write(pickle.dumps(got))\n"
        "print('keras' in sys.modules, policy.speed_head)\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=300, check=True)
    assert done.stdout.split()[-2:] == ["False", "True"]  # no Keras imported; speed head seen
    got = pickle.loads((tmp_path / "got.pkl").read_bytes())
    for (steering, speed), (want_steering, want_speed) in zip(got, want, strict=True):
        np.testing.assert_array_equal(steering, want_steering)
        np.testing.assert_array_equal(speed, want_speed)
    with pytest.raises(ValueError, match=r"no trace for a batch of 5 frames \(traced: \[2\]"):
        TracedModel(portable).predict_on_batch(np.concatenate([real_frames[:5]]))
    # Without mirror averaging the one batch is the frame itself.
    plain = NetworkPolicy(model)
    portable = plain.portable()
    assert sorted(portable.traces) == [1]
    worker = NetworkPolicy(TracedModel(portable), **plain.options())
    for mine, theirs in zip(worker.predict(frames), plain.predict(frames), strict=True):
        np.testing.assert_array_equal(mine, theirs)


def test_a_model_that_does_not_trace_exactly_is_not_made_portable(real_frames) -> None:
    model = untraceable_model()
    assert NetworkPolicy(model).portable() is None  # its workers load the model file instead
    pytest.importorskip("onnxruntime")
    from clonedrive.network.onnx_runtime import OnnxModel, onnx_bytes

    assert NetworkPolicy(OnnxModel(onnx_bytes(build_model("fast", seed=1)))).portable() is None


def test_a_size_this_process_does_not_run_traced_is_not_made_portable(real_frames) -> None:
    """Where this process found a batch size not to trace exactly (and so predicts it with
    Keras), the workers must not get a trace for it that passed on other frames: they would
    steer differently from an evaluation in this process."""
    policy = NetworkPolicy(build_model("fast", seed=1))
    policy.forward._traces[(1, *real_frames.shape[1:])] = None  # found not exact on its frames
    assert policy.portable() is None
    fresh = NetworkPolicy(build_model("fast", seed=1)).portable()
    assert sorted(fresh.traces) == [1] and all(fresh.traces.values())  # its one size traced
