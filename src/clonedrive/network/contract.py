"""The contract between a steering model and everything that trains, loads or drives it.

The model takes the center camera as RGB uint8-valued ``(160, 320, 3)`` (all preprocessing is
inside the model) and predicts steering in [-1, 1] (= wheel angle / 25 deg), its (first) output
named :data:`STEERING_OUTPUT`. A model may have a **speed head**: a second output named
:data:`SPEED_OUTPUT` predicting the expert's target speed for the scene, normalised by
:data:`TARGET_SPEED_SCALE_MPH` (1.0 = the car's top speed).

Outputs are checked when a model is loaded (:func:`check_model`, called by
:func:`clonedrive.network.model_file.load_model`): one output, the steering, shape ``(N, 1)``,
or the speed head's two; any other count, name or shape is refused at load with the names
found, instead of failing on every frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from clonedrive.base.udacity_spec import IMAGE_SHAPE
from clonedrive.world.vehicle import MPH_TO_MPS, VehicleParams

if TYPE_CHECKING:
    import keras

STEERING_OUTPUT = "steering"  #: name of a model's (first) output
SPEED_OUTPUT = "target_speed"  #: name of the optional second output, the speed head
#: A speed head's output 1.0 means this many mph: the car's top speed.
TARGET_SPEED_SCALE_MPH = VehicleParams.top_speed_mps / MPH_TO_MPS


def has_speed_head(model: keras.Model) -> bool:
    """True if ``model``'s second output is the speed head (:data:`SPEED_OUTPUT`)."""
    names = list(getattr(model, "output_names", None) or [])
    return len(names) == 2 and names[1] == SPEED_OUTPUT


def check_model(model: keras.Model) -> None:
    """Raise ``ValueError`` unless ``model`` takes one (None, 160, 320, 3) input and has one
    output (steering) or two (steering, then the speed head :data:`SPEED_OUTPUT`)."""
    inputs = getattr(model, "inputs", None)
    if not inputs or len(inputs) != 1:
        raise ValueError("the steering model must have exactly one input (the center camera)")
    shape = tuple(inputs[0].shape)[1:]
    if len(shape) != 3 or any(
        dim is not None and dim != want for dim, want in zip(shape, IMAGE_SHAPE, strict=True)
    ):
        raise ValueError(
            f"the steering model's input is {shape}, expected {IMAGE_SHAPE} (RGB, uint8 values; "
            "preprocessing belongs inside the model)"
        )
    outputs = list(getattr(model, "outputs", None) or [])
    if not outputs:
        raise ValueError("the steering model has no output")
    if len(outputs) == 2 and not has_speed_head(model):
        names = ", ".join(map(str, getattr(model, "output_names", [])))
        raise ValueError(
            f"the steering model has two outputs ({names}); a second output must be named "
            f"{SPEED_OUTPUT!r} (the speed head)"
        )
    if len(outputs) > 2:
        raise ValueError(
            f"the steering model has {len(outputs)} outputs; expected 1 (steering) or 2 "
            f"(steering, {SPEED_OUTPUT})"
        )
    names = [str(name) for name in (getattr(model, "output_names", None) or [])]
    for index, output in enumerate(outputs):
        shape = tuple(getattr(output, "shape", ()))[1:]
        if shape not in ((1,), (None,)):
            label = names[index] if index < len(names) else f"output {index}"
            raise ValueError(
                f"the steering model's {label!r} output has shape {shape} per image, "
                "expected (1,): one value"
            )
