"""Keras 3 steering networks: ``seed`` (the write-up's), ``pilotnet`` (NVIDIA 2016), ``fast``.

Every model takes one 160x320 RGB camera frame with uint8 values and returns one steering
value in [-1, 1]-ish units (wheel angle / 25 deg), shape ``(N, 1)``, from the output layer
``steering``. With ``speed_head=True`` it has a second output, the layer ``target_speed``
(``(N, 1)``, a Dense unit beside ``steering`` on the last hidden layer): the expert's target
speed here divided by ``network.contract.TARGET_SPEED_SCALE_MPH`` (1.0 = the car's top speed).
The input layer is
declared ``uint8``: float32 frames holding whole numbers 0..255 (what ``astype(np.float32)``
of a camera frame gives) are converted exactly; the cast to float happens after cropping,
which saves converting the 105 cropped rows of every frame (about 5% of a training step).
All preprocessing -- crop, resize, colour conversion, normalisation -- is done by built-in
layers inside the model, so whoever feeds the model a 160x320 RGB frame (the trainer, the
drive server, the evaluator) gets the same answer, and every model loads with
``keras.saving.load_model(path, safe_mode=True)`` (no ``Lambda`` layers).

Weight initialisers get explicit seeds derived from ``seed``, so building a model twice with
the same seed gives identical weights without touching any global random state.

Channel order (``data_format``): the input is always channels-last (N, 160, 320, 3), as
cameras and the drive protocol deliver it. With ``data_format="channels_first"`` (the default)
a ``Permute((3, 1, 2))`` layer named ``channels_first`` follows the preprocessing and the
convolutions run channels-first. On Keras's torch backend a channels-last ``Conv2D`` copies
its input twice per call (NHWC -> contiguous NCHW -> channels-last memory), which made
training ``seed`` about 1.5x slower than the same network in plain PyTorch; channels-first
convolutions need no copy. Both orders have the same layers otherwise, the same parameter
count and compute the same family of functions (Flatten merely lists the features in another
order); ``data_format="channels_last"`` gives the literal layer sequence of the write-up.
"""

from __future__ import annotations

import numpy as np

from clonedrive.base.keras_backend import import_keras
from clonedrive.base.udacity_spec import IMAGE_HEIGHT, IMAGE_SHAPE
from clonedrive.network.contract import SPEED_OUTPUT, STEERING_OUTPUT
from clonedrive.network.crop import CROP_BOTTOM_PX, CROP_TOP_PX

keras = import_keras()
layers = keras.layers


MODEL_NAMES = ("seed", "pilotnet", "fast")
DATA_FORMATS = ("channels_first", "channels_last")

# BT.601 RGB -> YUV for RGB in [0, 1]; rows are output channels Y, U, V.
_RGB_TO_YUV = np.array(
    [
        [0.299, 0.587, 0.114],
        [-0.14713, -0.28886, 0.436],
        [0.615, -0.51499, -0.10001],
    ],
    dtype=np.float64,
)
_UV_MAX = (0.436, 0.615)


class _Seeds:
    """Hands out one distinct initialiser seed per layer."""

    def __init__(self, seed: int):
        self._next = int(seed) * 1000

    def glorot(self) -> keras.initializers.Initializer:
        self._next += 1
        return keras.initializers.GlorotUniform(seed=self._next)

    def next_int(self) -> int:
        self._next += 1
        return self._next


def _frame_input():
    return keras.Input(shape=IMAGE_SHAPE, dtype="uint8", name="image_rgb")


def _crop(inputs, crop_top_px: int = CROP_TOP_PX):
    if not 0 <= crop_top_px < IMAGE_HEIGHT - CROP_BOTTOM_PX - 40:
        raise ValueError(f"crop_top_px {crop_top_px}; expected 0 to "
                         f"{IMAGE_HEIGHT - CROP_BOTTOM_PX - 41}")
    return layers.Cropping2D(cropping=((int(crop_top_px), CROP_BOTTOM_PX), (0, 0)),
                             name="crop")(inputs)


def _check_data_format(data_format: str) -> None:
    if data_format not in DATA_FORMATS:
        raise ValueError(
            f"data_format {data_format!r}; expected one of: {', '.join(DATA_FORMATS)}"
        )


def _to_data_format(x, data_format: str):
    """Move channels first (a Permute layer) if the convolutions run channels-first."""
    _check_data_format(data_format)
    if data_format == "channels_first":
        return layers.Permute((3, 1, 2), name="channels_first")(x)
    return x


def _uint8_channels_first(crop):
    """The uint8 crop in channels-first order, laid out in memory as such.

    Up to 2026-12-06 ``fast`` scaled the crop to float and then pooled it channels-last; with
    PyTorch that pooling copies the float frame into channels-first order. Moving the channels
    while the frame is uint8 copies a quarter of the bytes. Permute alone only changes the
    strides, so a flatten and unflatten (Reshape) make the copy: the pooling and convolutions
    then see memory laid out as before and compute the same values to the bit (a different
    layout changes the convolutions' rounding, and training amplifies it).
    """
    rows, columns, channels = crop.shape[1:]
    x = layers.Permute((3, 1, 2), name="channels_first")(crop)
    x = layers.Reshape((-1,), name="flatten_channels_first")(x)
    return layers.Reshape((channels, rows, columns), name="frame_channels_first")(x)


def _heads(inputs, features, seeds: _Seeds, speed_head: bool, name: str) -> keras.Model:
    """The model with the ``steering`` output on the last hidden layer ``features`` (and, with
    ``speed_head``, the ``target_speed`` output beside it)."""
    steering = layers.Dense(1, kernel_initializer=seeds.glorot(), name=STEERING_OUTPUT)(features)
    if not speed_head:
        return keras.Model(inputs, steering, name=name)
    speed = layers.Dense(1, kernel_initializer=seeds.glorot(), name=SPEED_OUTPUT)(features)
    return keras.Model(inputs, [steering, speed], name=name)


def build_seed(
    *, seed: int = 0, dropout: float = 0.0, l2: float = 1e-3,
    data_format: str = "channels_first", speed_head: bool = False,
    crop_top_px: int = CROP_TOP_PX,
) -> keras.Model:
    """The write-up's network.

    Input 160x320x3 -> Cropping2D(((80, 25), (0, 0))) -> Rescaling(1/127.5, offset=-1) ->
    [Permute to channels-first, see module doc] -> Conv2D 36 5x5/2, 48 5x5/2, 64 3x3,
    64 3x3 (ReLU, L2 ``l2``) -> Flatten -> Dense 100, 50 (ReLU, L2 ``l2``) -> Dense 10 (ReLU)
    -> Dense 1. ``dropout`` > 0 inserts Dropout after Flatten and after Dense 100 and 50
    (off by default).
    """
    seeds = _Seeds(seed)
    reg = keras.regularizers.L2(l2)
    inputs = _frame_input()
    x = _crop(inputs, crop_top_px)
    x = layers.Rescaling(1.0 / 127.5, offset=-1.0, name="normalise")(x)
    x = _to_data_format(x, data_format)
    for index, (filters, size, stride) in enumerate(
        [(36, 5, 2), (48, 5, 2), (64, 3, 1), (64, 3, 1)], start=1
    ):
        x = layers.Conv2D(
            filters, size, strides=stride, activation="relu", kernel_regularizer=reg,
            kernel_initializer=seeds.glorot(), data_format=data_format, name=f"conv{index}",
        )(x)
    x = layers.Flatten(name="flatten")(x)
    if dropout > 0:
        x = layers.Dropout(dropout, seed=seeds.next_int(), name="dropout0")(x)
    for index, units in enumerate([100, 50], start=1):
        x = layers.Dense(
            units, activation="relu", kernel_regularizer=reg,
            kernel_initializer=seeds.glorot(), name=f"dense{index}",
        )(x)
        if dropout > 0:
            x = layers.Dropout(dropout, seed=seeds.next_int(), name=f"dropout{index}")(x)
    x = layers.Dense(10, activation="relu", kernel_initializer=seeds.glorot(), name="dense3")(x)
    return _heads(inputs, x, seeds, speed_head, "seed")


def _rgb_to_yuv_layer(data_format: str) -> layers.Conv2D:
    """A frozen 1x1 convolution mapping RGB in [0, 1] to YUV scaled to about [-1, 1]."""
    return layers.Conv2D(
        3, 1, use_bias=True, trainable=False, data_format=data_format, name="rgb_to_yuv"
    )


def _rgb_to_yuv_weights() -> list[np.ndarray]:
    # y' = 2 * Y - 1, u' = U / 0.436, v' = V / 0.615 so each channel spans [-1, 1].
    scale = np.array([2.0, 1.0 / _UV_MAX[0], 1.0 / _UV_MAX[1]])
    matrix = _RGB_TO_YUV * scale[:, None]  # (out, in)
    kernel = matrix.T.reshape(1, 1, 3, 3).astype(np.float32)  # (h, w, in, out)
    bias = np.array([-1.0, 0.0, 0.0], dtype=np.float32)
    return [kernel, bias]


def build_pilotnet(
    *, seed: int = 0, dropout: float = 0.0, data_format: str = "channels_first",
    speed_head: bool = False, crop_top_px: int = CROP_TOP_PX,
) -> keras.Model:
    """NVIDIA's PilotNet (Bojarski et al. 2016) fed like the paper: 66x200 YUV.

    Input 160x320x3 RGB -> crop (80, 25) -> Rescaling(1/255) -> Resizing(66, 200) ->
    [Permute to channels-first] -> frozen 1x1 Conv2D RGB->YUV (each channel scaled to
    [-1, 1]) -> Conv2D 24, 36, 48 (5x5/2) and 64, 64 (3x3) -> Flatten -> Dense 100, 50, 10
    -> Dense 1; ReLU.
    """
    seeds = _Seeds(seed)
    inputs = _frame_input()
    x = _crop(inputs, crop_top_px)
    x = layers.Rescaling(1.0 / 255.0, name="unit_range")(x)
    x = layers.Resizing(66, 200, interpolation="bilinear", name="resize")(x)
    x = _to_data_format(x, data_format)
    yuv = _rgb_to_yuv_layer(data_format)
    x = yuv(x)
    yuv.set_weights(_rgb_to_yuv_weights())
    for index, (filters, size, stride) in enumerate(
        [(24, 5, 2), (36, 5, 2), (48, 5, 2), (64, 3, 1), (64, 3, 1)], start=1
    ):
        x = layers.Conv2D(
            filters, size, strides=stride, activation="relu",
            kernel_initializer=seeds.glorot(), data_format=data_format, name=f"conv{index}",
        )(x)
    x = layers.Flatten(name="flatten")(x)
    for index, units in enumerate([100, 50, 10], start=1):
        x = layers.Dense(
            units, activation="relu", kernel_initializer=seeds.glorot(), name=f"dense{index}"
        )(x)
        if dropout > 0 and index < 3:
            x = layers.Dropout(dropout, seed=seeds.next_int(), name=f"dropout{index}")(x)
    return _heads(inputs, x, seeds, speed_head, "pilotnet")


def build_fast(
    *, seed: int = 0, dropout: float = 0.0, data_format: str = "channels_first",
    speed_head: bool = False, crop_top_px: int = CROP_TOP_PX,
) -> keras.Model:
    """A small network (about 89k parameters) that trains in minutes on 2 CPU cores.

    Input 160x320x3 -> crop (80, 25) -> 55x320 -> [channels first, still uint8] -> Rescaling to
    [-1, 1] -> AveragePooling2D (2, 2) -> 27x160 -> Conv2D 16 5x5 stride (2, 2) -> 12x78 ->
    Conv2D 32 3x3 stride (1, 2) -> 10x38 -> Conv2D 32 3x3 stride (2, 2) -> 4x18 -> Flatten ->
    Dense 32 -> Dense 1; ReLU.
    """
    _check_data_format(data_format)
    seeds = _Seeds(seed)
    inputs = _frame_input()
    x = _crop(inputs, crop_top_px)
    if data_format == "channels_first":
        x = _uint8_channels_first(x)
    x = layers.Rescaling(1.0 / 127.5, offset=-1.0, name="normalise")(x)
    x = layers.AveragePooling2D(pool_size=(2, 2), data_format=data_format, name="downsample")(x)
    for index, (filters, size, stride) in enumerate(
        [(16, 5, (2, 2)), (32, 3, (1, 2)), (32, 3, (2, 2))], start=1
    ):
        x = layers.Conv2D(
            filters, size, strides=stride, activation="relu",
            kernel_initializer=seeds.glorot(), data_format=data_format, name=f"conv{index}",
        )(x)
    x = layers.Flatten(name="flatten")(x)
    if dropout > 0:
        x = layers.Dropout(dropout, seed=seeds.next_int(), name="dropout0")(x)
    x = layers.Dense(32, activation="relu", kernel_initializer=seeds.glorot(), name="dense1")(x)
    return _heads(inputs, x, seeds, speed_head, "fast")


_BUILDERS = {"seed": build_seed, "pilotnet": build_pilotnet, "fast": build_fast}


def build_model(name: str, **options) -> keras.Model:
    """Build the named architecture (``seed``, ``pilotnet`` or ``fast``).

    ``options`` are passed to the builder: ``seed`` (int, initialiser seed), ``dropout``
    (float, 0 = off), ``data_format`` (``channels_first``, the default, or
    ``channels_last``; see the module doc), ``speed_head`` (bool, the second output
    ``target_speed``; see the module doc), ``crop_top_px`` (rows cut from the top, default
    :data:`clonedrive.network.crop.CROP_TOP_PX`) and, for ``seed`` only, ``l2``.
    """
    try:
        builder = _BUILDERS[name]
    except KeyError:
        raise ValueError(
            f"unknown model {name!r}; expected one of: {', '.join(MODEL_NAMES)}"
        ) from None
    return builder(**options)
