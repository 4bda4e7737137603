"""A tiny, deterministic steering network with the Udacity model contract.

Input RGB uint8-valued ``(160, 320, 3)``, preprocessing inside the model (``Rescaling``,
``Cropping2D``), one steering output. It exists so that tests, benchmarks and smoke runs of the
serving path have a real Keras model that builds in a fraction of a second; it cannot drive.

:func:`build_road_follower` is as small and needs no training either, but it does drive: its
weights are set by hand to steer away from the grass it sees on either side of the road.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import keras


def build_tiny_model(seed: int = 0) -> keras.Model:
    """Rescaling -> Cropping2D -> one strided conv -> global average -> Dense(1), seeded weights."""
    from clonedrive.base.keras_backend import import_keras
    from clonedrive.base.udacity_spec import IMAGE_SHAPE

    keras = import_keras()
    from keras import layers

    inputs = keras.Input(shape=IMAGE_SHAPE, name="center_rgb")
    x = layers.Rescaling(1.0 / 127.5, offset=-1.0)(inputs)
    x = layers.Cropping2D(cropping=((60, 20), (0, 0)))(x)
    x = layers.Conv2D(
        8,
        5,
        strides=4,
        activation="relu",
        kernel_initializer=keras.initializers.GlorotUniform(seed=seed),
    )(x)
    x = layers.GlobalAveragePooling2D()(x)
    outputs = layers.Dense(
        1, activation="tanh", kernel_initializer=keras.initializers.GlorotUniform(seed=seed + 1)
    )(x)
    return keras.Model(inputs, outputs, name="tiny_steering")


def build_road_follower(gain: float = 10.0, *, grass_threshold: float = 0.08,
                        columns: int = 8) -> keras.Model:
    """A hand-weighted network that keeps the car on the road (scenery off, daylight themes).

    Below the horizon and above the bonnet, a 1x1 convolution marks grass (green minus blue
    above ``grass_threshold``: asphalt is grey); ``columns`` average-pooled strips measure how
    much grass each part of the picture holds, and the steering is
    ``tanh(gain * (grass on the left - grass on the right))``: more grass on the right means
    the car drifts right, or the road bends left, so it steers left. It follows the road like
    a slow pure pursuit: good enough for closed-loop tests that need laps completed (and, at a
    speed too high for a bend, interventions) without training a model. Safe-mode loadable.
    """
    import numpy as np

    from clonedrive.base.keras_backend import import_keras
    from clonedrive.base.udacity_spec import IMAGE_HEIGHT, IMAGE_SHAPE, IMAGE_WIDTH

    if columns < 2 or columns % 2 or IMAGE_WIDTH % columns:
        raise ValueError(f"columns must be even and divide {IMAGE_WIDTH}, got {columns}")
    keras = import_keras()
    from keras import layers

    top, bottom = 75, 30  # rows above the horizon and of the bonnet, cropped away
    inputs = keras.Input(shape=IMAGE_SHAPE, name="center_rgb")
    x = layers.Rescaling(1.0 / 255.0)(inputs)
    x = layers.Cropping2D(cropping=((top, bottom), (0, 0)))(x)
    grass = layers.Conv2D(1, 1, activation="relu", name="grass")(x)
    x = layers.AveragePooling2D(pool_size=(IMAGE_HEIGHT - top - bottom, IMAGE_WIDTH // columns)
                                )(grass)
    x = layers.Flatten()(x)
    outputs = layers.Dense(1, activation="tanh", name="steering")(x)
    model = keras.Model(inputs, outputs, name="road_follower")
    green_minus_blue = np.array([0.0, 1.0, -1.0], np.float32).reshape(1, 1, 3, 1)
    model.get_layer("grass").set_weights(
        [green_minus_blue, np.array([-grass_threshold], np.float32)])
    half = columns // 2
    sides = np.array([1.0] * half + [-1.0] * half, np.float32) * (gain / half)
    model.get_layer("steering").set_weights([sides.reshape(columns, 1), np.zeros(1, np.float32)])
    return model
