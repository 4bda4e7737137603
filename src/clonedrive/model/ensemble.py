"""Several trained steering networks as one model: the mean of their outputs.

A network's steering varies from frame to frame by more than the road does (about 0.02 on
open road where the expert's label barely moves: ``benchmarks/jitter.py``), and that noise is
the network's own: two networks trained alike from other seeds err differently on the same
frame. The mean of K of them keeps what they agree on, the road, and cancels part of the rest.

:func:`build_ensemble` wraps the members in one functional Keras model: the same input (the
160x320 RGB frame, uint8 values), each member as a nested model (its own crop and
preprocessing), and an ``Average`` per output named as the members' (``steering``, and
``target_speed`` when every member has the speed head). The result is an ordinary model file:
it loads in safe mode (no ``Lambda``), and ``drive``, ``evaluate``, ``bench`` and ``export``
take it as they take any model; it costs K members' inference.
"""

from __future__ import annotations

from collections.abc import Sequence

from clonedrive.base.keras_backend import import_keras
from clonedrive.base.udacity_spec import IMAGE_SHAPE
from clonedrive.network.contract import SPEED_OUTPUT, STEERING_OUTPUT, check_model, has_speed_head

#: The most members one ensemble may have (each adds a network's inference per frame).
MAX_MEMBERS = 16


def build_ensemble(models: Sequence, *, name: str = "ensemble"):
    """One Keras model whose outputs are the means of ``models``' outputs (see the module doc).

    Every member must pass :func:`~clonedrive.network.contract.check_model`, and either all have
    the speed head or none. Raises ``ValueError`` otherwise, naming the member (by position).
    The members are renamed ``member1`` ... and frozen (an ensemble is for driving).
    """
    keras = import_keras()
    layers = keras.layers
    members = list(models)
    if len(members) < 2:
        raise ValueError(f"an ensemble needs at least 2 models, got {len(members)}")
    if len(members) > MAX_MEMBERS:
        raise ValueError(f"an ensemble takes at most {MAX_MEMBERS} models, got {len(members)}")
    heads = []
    for position, member in enumerate(members, start=1):
        try:
            check_model(member)
        except ValueError as error:
            raise ValueError(f"model {position}: {error}") from None
        heads.append(has_speed_head(member))
    if len(set(heads)) != 1:
        with_head = [str(i) for i, head in enumerate(heads, start=1) if head]
        raise ValueError(f"models {', '.join(with_head)} have a speed head and the others do "
                         "not: an ensemble's members must all have it or all lack it")
    inputs = keras.Input(shape=IMAGE_SHAPE, dtype="uint8", name="image_rgb")
    steering, speed = [], []
    for position, member in enumerate(members, start=1):
        member.name = f"member{position}"  # nested models need distinct names to be saved
        # Frozen: an ensemble is for driving, and PyTorch can then trace it (network.traced
        # cannot embed weights that require gradients).
        member.trainable = False
        outputs = member(inputs)
        outputs = list(outputs) if isinstance(outputs, list | tuple) else [outputs]
        steering.append(outputs[0])
        if heads[0]:
            speed.append(outputs[1])
    mean_steering = layers.Average(name=STEERING_OUTPUT)(steering)
    if not heads[0]:
        return keras.Model(inputs, mean_steering, name=name)
    mean_speed = layers.Average(name=SPEED_OUTPUT)(speed)
    return keras.Model(inputs, [mean_steering, mean_speed], name=name)
