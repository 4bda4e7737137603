"""A tiny, deterministic steering network with the Udacity model contract.

Input RGB uint8-valued ``(160, 320, 3)``, preprocessing inside the model (``Rescaling``,
``Cropping2D``), one steering output. It exists so that tests, benchmarks and smoke runs of the
serving path have a real Keras model that builds in a fraction of a second; it cannot drive.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import keras


def build_tiny_model(seed: int = 0) -> keras.Model:
    """Rescaling -> Cropping2D -> one strided conv -> global average -> Dense(1), seeded weights."""
    from clonedrive.keras_backend import import_keras
    from clonedrive.udacity_spec import IMAGE_SHAPE

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
