"""The three steering networks: layer sequences, sizes, preprocessing inside, safe save/load."""

from __future__ import annotations

from pathlib import Path

import keras
import numpy as np
import pytest

from clonedrive.model.architectures import MODEL_NAMES, build_model

FRAMES = np.random.default_rng(5).integers(0, 256, size=(3, 160, 320, 3)).astype(np.uint8)

# (layer name, class name, output shape without batch) in model order.
SEED_LAYERS = [
    ("image_rgb", "InputLayer", (160, 320, 3)),
    ("crop", "Cropping2D", (55, 320, 3)),
    ("normalise", "Rescaling", (55, 320, 3)),
    ("conv1", "Conv2D", (26, 158, 36)),
    ("conv2", "Conv2D", (11, 77, 48)),
    ("conv3", "Conv2D", (9, 75, 64)),
    ("conv4", "Conv2D", (7, 73, 64)),
    ("flatten", "Flatten", (32704,)),
    ("dense1", "Dense", (100,)),
    ("dense2", "Dense", (50,)),
    ("dense3", "Dense", (10,)),
    ("steering", "Dense", (1,)),
]
PILOTNET_LAYERS = [
    ("image_rgb", "InputLayer", (160, 320, 3)),
    ("crop", "Cropping2D", (55, 320, 3)),
    ("unit_range", "Rescaling", (55, 320, 3)),
    ("resize", "Resizing", (66, 200, 3)),
    ("rgb_to_yuv", "Conv2D", (66, 200, 3)),
    ("conv1", "Conv2D", (31, 98, 24)),
    ("conv2", "Conv2D", (14, 47, 36)),
    ("conv3", "Conv2D", (5, 22, 48)),
    ("conv4", "Conv2D", (3, 20, 64)),
    ("conv5", "Conv2D", (1, 18, 64)),
    ("flatten", "Flatten", (1152,)),
    ("dense1", "Dense", (100,)),
    ("dense2", "Dense", (50,)),
    ("dense3", "Dense", (10,)),
    ("steering", "Dense", (1,)),
]


def _conv(k: int, c_in: int, c_out: int) -> int:
    return k * k * c_in * c_out + c_out


def _dense(n_in: int, n_out: int) -> int:
    return n_in * n_out + n_out


SEED_PARAMS = (
    _conv(5, 3, 36) + _conv(5, 36, 48) + _conv(3, 48, 64) + _conv(3, 64, 64)
    + _dense(32704, 100) + _dense(100, 50) + _dense(50, 10) + _dense(10, 1)
)
PILOTNET_PARAMS = (
    _conv(1, 3, 3)  # the frozen RGB->YUV layer
    + _conv(5, 3, 24) + _conv(5, 24, 36) + _conv(5, 36, 48) + _conv(3, 48, 64) + _conv(3, 64, 64)
    + _dense(1152, 100) + _dense(100, 50) + _dense(50, 10) + _dense(10, 1)
)


def _layers(model: keras.Model) -> list[tuple[str, str, tuple]]:
    return [
        (layer.name, type(layer).__name__, tuple(layer.output.shape[1:])) for layer in model.layers
    ]


def _channels_first(sequence: list[tuple[str, str, tuple]], after: str) -> list:
    """The channels-last layer list as the default build has it: a Permute after ``after``,
    then (C, H, W) shapes up to Flatten."""
    result, permuted = [], False
    for name, kind, shape in sequence:
        if permuted and len(shape) == 3:
            shape = (shape[2], shape[0], shape[1])
        result.append((name, kind, shape))
        if name == after:
            result.append(("channels_first", "Permute", (shape[2], shape[0], shape[1])))
            permuted = True
    return result


def test_seed_is_exactly_the_writeups_network() -> None:
    assert _layers(build_model("seed", data_format="channels_last")) == SEED_LAYERS
    model = build_model("seed")
    assert _layers(model) == _channels_first(SEED_LAYERS, after="normalise")
    assert model.count_params() == SEED_PARAMS == 3_386_695
    crop = model.get_layer("crop")
    assert crop.cropping == ((80, 25), (0, 0))
    normalise = model.get_layer("normalise")
    assert normalise.scale == pytest.approx(1 / 127.5) and normalise.offset == -1.0
    strides = {name: model.get_layer(name).strides for name in ("conv1", "conv2", "conv3", "conv4")}
    assert strides == {"conv1": (2, 2), "conv2": (2, 2), "conv3": (1, 1), "conv4": (1, 1)}
    regularised = {
        layer.name
        for layer in model.layers
        if getattr(layer, "kernel_regularizer", None) is not None
    }
    assert regularised == {"conv1", "conv2", "conv3", "conv4", "dense1", "dense2"}
    assert model.get_layer("conv1").kernel_regularizer.l2 == pytest.approx(1e-3)
    activations = [
        layer.activation.__name__ for layer in model.layers if hasattr(layer, "activation")
    ]
    assert activations == ["relu"] * 7 + ["linear"]
    assert not any(type(layer).__name__ == "Dropout" for layer in model.layers)


def test_seed_dropout_is_optional() -> None:
    model = build_model("seed", dropout=0.3)
    dropouts = [layer for layer in model.layers if type(layer).__name__ == "Dropout"]
    assert len(dropouts) == 3 and all(layer.rate == 0.3 for layer in dropouts)
    assert model.count_params() == SEED_PARAMS


def test_pilotnet_layers_and_frozen_yuv_conversion() -> None:
    assert _layers(build_model("pilotnet", data_format="channels_last")) == PILOTNET_LAYERS
    model = build_model("pilotnet")
    assert _layers(model) == _channels_first(PILOTNET_LAYERS, after="resize")
    assert model.count_params() == PILOTNET_PARAMS
    yuv = model.get_layer("rgb_to_yuv")
    assert not yuv.trainable
    assert model.count_params() - sum(int(np.prod(w.shape)) for w in model.trainable_weights) == 12
    # White -> Y' = 1, U' = V' = 0; black -> Y' = -1; pure red -> V' = +1 (0.615 / 0.615).
    probe = keras.Model(model.input, yuv.output)
    frames = np.zeros((3, 160, 320, 3), dtype=np.float32)
    frames[0] = 255.0
    frames[2, ..., 0] = 255.0
    out = np.asarray(probe.predict(frames, verbose=0))[:, :, 30, 100]  # (N, C, H, W)
    np.testing.assert_allclose(out[0], [1.0, 0.0, 0.0], atol=1e-4)
    np.testing.assert_allclose(out[1], [-1.0, 0.0, 0.0], atol=1e-4)
    np.testing.assert_allclose(out[2, 2], 1.0, atol=1e-4)


def test_fast_is_small() -> None:
    model = build_model("fast")
    assert model.count_params() < 100_000
    assert [type(layer).__name__ for layer in model.layers[:7]] == [
        "InputLayer", "Cropping2D", "Permute", "Reshape", "Reshape", "Rescaling",
        "AveragePooling2D",
    ]


def _in_previous_order(model: keras.Model) -> keras.Model:
    """``model``'s layers from the first convolution on, after the preprocessing in the order
    ``fast`` had up to 2026-12-06: scaled, pooled channels-last, then channels moved first."""
    inputs = keras.Input(shape=(160, 320, 3), dtype="uint8")
    x = keras.layers.Cropping2D(model.get_layer("crop").cropping)(inputs)
    x = keras.layers.Rescaling(1.0 / 127.5, offset=-1.0)(x)
    x = keras.layers.AveragePooling2D(pool_size=(2, 2))(x)
    x = keras.layers.Permute((3, 1, 2))(x)
    for name in ("conv1", "conv2", "conv3", "flatten", "dense1"):
        x = model.get_layer(name)(x)
    return keras.Model(inputs, [model.get_layer(name)(x)
                                for name in ("steering", "target_speed")])


def test_fast_computes_what_its_previous_layer_order_did_to_the_bit() -> None:
    """The layout change is for speed only: a different memory layout changes the
    convolutions' rounding, and training would amplify that into a different model."""
    model = build_model("fast", seed=4, speed_head=True, crop_top_px=60)
    frames = np.random.default_rng(4).integers(0, 256, (8, 160, 320, 3), dtype=np.uint8)
    for new, old in zip(model.predict_on_batch(frames),
                        _in_previous_order(model).predict_on_batch(frames), strict=True):
        assert np.array_equal(np.asarray(new), np.asarray(old))


@pytest.mark.parametrize("data_format", ["channels_first", "channels_last"])
def test_fast_downsamples_the_crop_to_minus_one_to_one(data_format: str) -> None:
    """The uint8 crop is scaled to [-1, 1] and averaged over 2x2 blocks in either layout."""
    model = build_model("fast", crop_top_px=60, data_format=data_format)
    probe = keras.Model(model.inputs[0], model.get_layer("downsample").output)
    frames = np.random.default_rng(3).integers(0, 256, (2, 160, 320, 3), dtype=np.uint8)
    crop = frames[:, 60:135].astype(np.float64) / 127.5 - 1.0
    expected = crop[:, :74].reshape(2, 37, 2, 160, 2, 3).mean(axis=(2, 4))
    out = np.asarray(probe.predict(frames, verbose=0))
    if data_format == "channels_first":
        out = out.transpose(0, 2, 3, 1)
    np.testing.assert_allclose(out, expected, atol=1e-5)


def test_unknown_model_name_is_an_error() -> None:
    with pytest.raises(ValueError, match="unknown model 'resnet'.*seed, pilotnet, fast"):
        build_model("resnet")
    with pytest.raises(ValueError, match="data_format 'nhwc'"):
        build_model("seed", data_format="nhwc")
    with pytest.raises(ValueError, match="data_format 'nhwc'"):
        build_model("fast", data_format="nhwc")


def test_channel_orders_compute_the_same_function() -> None:
    """Same weights (Dense 100's input rows reordered as Flatten lists them) -> same output."""
    last = build_model("seed", seed=2, data_format="channels_last")
    first = build_model("seed", seed=2)
    assert first.count_params() == last.count_params()
    for name in ("conv1", "conv2", "conv3", "conv4", "dense2", "dense3", "steering"):
        for a, b in zip(first.get_layer(name).get_weights(), last.get_layer(name).get_weights(),
                        strict=True):
            np.testing.assert_array_equal(a, b)  # same seeds, same shapes
    kernel, bias = last.get_layer("dense1").get_weights()
    reordered = kernel.reshape(7, 73, 64, 100).transpose(2, 0, 1, 3).reshape(32704, 100)
    first.get_layer("dense1").set_weights([reordered, bias])
    np.testing.assert_allclose(
        np.asarray(first.predict(FRAMES, verbose=0)), np.asarray(last.predict(FRAMES, verbose=0)),
        rtol=1e-4, atol=1e-5,
    )


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_save_load_safe_mode_and_h5_give_identical_predictions(name: str, tmp_path: Path) -> None:
    model = build_model(name, seed=3)
    assert not any(type(layer).__name__ == "Lambda" for layer in model.layers)
    expected = np.asarray(model.predict(FRAMES, verbose=0))
    assert expected.shape == (3, 1)
    assert model.input.dtype == "uint8"
    # uint8 frames and their float32 copies give the same answer (the model casts).
    np.testing.assert_array_equal(
        np.asarray(model.predict(FRAMES.astype(np.float32), verbose=0)), expected
    )
    model.save(tmp_path / "m.keras")
    loaded = keras.saving.load_model(tmp_path / "m.keras", safe_mode=True)
    np.testing.assert_array_equal(np.asarray(loaded.predict(FRAMES, verbose=0)), expected)
    model.save(tmp_path / "m.h5")
    from_h5 = keras.saving.load_model(tmp_path / "m.h5", safe_mode=True, compile=False)
    np.testing.assert_allclose(np.asarray(from_h5.predict(FRAMES, verbose=0)), expected,
                               rtol=0, atol=1e-6)


def test_same_seed_same_weights_without_global_seeding() -> None:
    first = build_model("fast", seed=11).get_weights()
    second = build_model("fast", seed=11).get_weights()
    other = build_model("fast", seed=12).get_weights()
    assert all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))
    assert not np.array_equal(first[0], other[0])
