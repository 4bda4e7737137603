"""Losses of the speed head (``train --speed-loss``).

The speed label is the expert's target speed over the car's top speed, so on every straight it
is exactly 1.0: the expert would go faster if the car could. About two thirds of the demo's
labels sit there. Plain MSE could then pull the prediction on a straight below that bound,
towards the mean of frames that look alike, some of them before a bend, and so slow the car
on open road.

``censored``: a label at the top speed is read as "at least the top speed" (a censored
observation, as in Tobit regression). Predicting above it costs nothing (the policy caps the
learned speed at the set speed anyway); predicting below costs the squared shortfall. Every
other label is plain MSE. The default is ``mse``; what ``censored`` measured is in the
documentation's results.
"""

from __future__ import annotations

from clonedrive.data.speed_labels import SATURATED_LABEL

#: The speed losses ``TrainConfig.speed_loss`` takes.
SPEED_LOSSES = ("mse", "censored")


def censored_speed_mse(y_true, y_pred):
    """Per-sample squared error, with labels at the top speed read as lower bounds."""
    from keras import ops

    y_true = ops.cast(y_true, y_pred.dtype)
    error = y_true - y_pred
    bound = ops.greater_equal(y_true, SATURATED_LABEL)
    error = ops.where(bound, ops.maximum(error, 0.0), error)
    return ops.mean(ops.square(error), axis=-1)


def speed_loss(name: str):
    """What ``model.compile`` takes as the speed output's loss for ``name``."""
    if name not in SPEED_LOSSES:
        raise ValueError(f"speed loss {name!r}; expected one of: {', '.join(SPEED_LOSSES)}")
    return "mse" if name == "mse" else censored_speed_mse


#: For loading a model compiled with these losses (resuming a run).
CUSTOM_OBJECTS = {"censored_speed_mse": censored_speed_mse}
