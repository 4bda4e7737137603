"""The steering loss of ``train --consistency W``: MSE plus a penalty on frame-to-frame noise.

Batches come as N samples followed by their N next frames (:func:`clonedrive.data.neighbours.
next_frames`, augmented alike). For a pair ``(a, b)`` the penalty is

    W * ((p_a - p_b) - (y_a - y_b))**2  =  W * (e_a - e_b)**2,   e = prediction - label,

the part of the change between two frames 1/15 s apart that the expert's labels do not
explain. Plain MSE only asks each error to be small; this asks neighbouring errors to be
alike, so what error remains varies slowly and a hold on the wheel (``--steering-hold``) is not
kicked from frame to frame. A sample with no next frame is paired with itself: its penalty is 0.
Each sample carries its pair's penalty, so the mean over the batch is MSE + W * mean pair term.
"""

from __future__ import annotations

from clonedrive.base.keras_backend import import_keras

keras = import_keras()


class ConsistentMSE(keras.losses.Loss):
    """Per-sample ``(p - y)**2 + weight * (e_a - e_b)**2`` over a batch of pairs (module doc)."""

    def __init__(self, weight: float = 1.0, name: str = "consistent_mse", **kwargs) -> None:
        super().__init__(name=name, **kwargs)
        self.weight = float(weight)

    def call(self, y_true, y_pred):
        from keras import ops

        y_pred = ops.reshape(y_pred, (-1,))
        y_true = ops.reshape(ops.cast(y_true, y_pred.dtype), (-1,))
        error = y_pred - y_true
        half = ops.shape(error)[0] // 2
        pair = ops.square(error[:half] - error[half:])
        return ops.square(error) + self.weight * ops.concatenate([pair, pair])

    def get_config(self) -> dict:
        return {**super().get_config(), "weight": self.weight}


#: For loading a model compiled with this loss (resuming a run).
CUSTOM_OBJECTS = {"ConsistentMSE": ConsistentMSE}
