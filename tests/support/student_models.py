"""Models built the way Udacity students built theirs, for the model-loading tests.

:func:`student_model` is the classic network in Keras 3: ``Lambda(lambda x: x / 255.0 - 0.5)``,
``Cropping2D(((70, 25), (0, 0)))``, NVIDIA's five ``Conv2D`` (narrowed here to stay small),
``Flatten``, ``Dense`` 100/50/10/1, seeded. ``model.save("x.h5")`` of it is a Keras-3-saved
``.h5`` with a Lambda.

:func:`write_keras2_h5` writes the same network as Keras 2.2.4 saved it on Python 3.6 (the
``model.h5`` of a 2018 student): HDF5 attributes ``keras_version`` / ``backend`` /
``model_config`` (Keras 2 layer configs), a ``model_weights`` group with ``layer_names`` and
per-layer ``weight_names`` (``conv2d_1/kernel:0``), and the Lambda's code as Keras 2's
``func_dump`` stored it: base64 of ``marshal`` data of a **Python 3.6** code object (3.6
wordcode, 3.6 code-object layout), which Python 3.11 cannot load. :func:`write_keras1_h5`
does the same for Keras 1.2 (``Convolution2D``, ``nb_filter``, ``subsample``, ``output_dim``,
``dim_ordering``; weights ``convolution2d_1_W``).
"""

from __future__ import annotations

import base64
import json
import marshal
import struct
from pathlib import Path

import h5py
import keras
import numpy as np
from keras import layers

INPUT_SHAPE = (160, 320, 3)
CROPPING = ((70, 25), (0, 0))
# (filters, kernel, stride): NVIDIA's layout with fewer filters, so the test model is small.
CONVOLUTIONS = ((6, 5, 2), (8, 5, 2), (10, 5, 2), (12, 3, 1), (12, 3, 1))
DENSE = (100, 50, 10, 1)


def student_model(seed: int = 0) -> keras.Model:
    """The student network in Keras 3 (names as Keras 2 gave them: conv2d_1, dense_1, ...)."""
    model = keras.Sequential(name="sequential_1")
    model.add(keras.Input(shape=INPUT_SHAPE))
    model.add(layers.Lambda(lambda x: x / 255.0 - 0.5, name="lambda_1"))
    model.add(layers.Cropping2D(cropping=CROPPING, name="cropping2d_1"))
    for index, (filters, size, stride) in enumerate(CONVOLUTIONS, start=1):
        model.add(layers.Conv2D(filters, size, strides=stride, activation="relu",
                                kernel_initializer=keras.initializers.GlorotUniform(seed + index),
                                name=f"conv2d_{index}"))
    model.add(layers.Flatten(name="flatten_1"))
    for index, units in enumerate(DENSE, start=1):
        model.add(layers.Dense(units, kernel_initializer=keras.initializers.GlorotUniform(
            seed + 10 + index), bias_initializer=keras.initializers.RandomUniform(
                -0.1, 0.1, seed + 20 + index), name=f"dense_{index}"))
    return model


# --------------------------------------------------------------------------- Python 3.6 marshal


def _long(value: int) -> bytes:
    return struct.pack("<i", value)


def _bytes(data: bytes) -> bytes:
    return b"s" + _long(len(data)) + data


def _short_ascii(text: str) -> bytes:
    return b"z" + bytes([len(text)]) + text.encode("ascii")


def _tuple(items: list[bytes]) -> bytes:
    return b")" + bytes([len(items)]) + b"".join(items)


def _float(value: float) -> bytes:
    return b"g" + struct.pack("<d", value)


# Python 3.6 opcodes (wordcode: opcode, argument).
_LOAD_FAST, _LOAD_CONST, _TRUE_DIVIDE, _SUBTRACT, _RETURN = 124, 100, 27, 24, 83


def python36_lambda_code(scale: float = 255.0, offset: float = 0.5,
                         *, names: tuple[str, ...] = ()) -> bytes:
    """``marshal.dumps((lambda x: x / scale - offset).__code__)`` as Python 3.6 wrote it.

    ``names``: global names the code refers to (as a Lambda calling ``tf.image...`` would).
    """
    code = bytes([_LOAD_FAST, 0, _LOAD_CONST, 1, _TRUE_DIVIDE, 0, _LOAD_CONST, 2, _SUBTRACT, 0,
                  _RETURN, 0])
    return b"".join([
        b"c",
        _long(1),  # co_argcount
        _long(0),  # co_kwonlyargcount
        _long(1),  # co_nlocals
        _long(2),  # co_stacksize
        _long(0x43),  # co_flags: OPTIMIZED | NEWLOCALS | NOFREE
        _bytes(code),
        _tuple([b"N", _float(scale), _float(offset)]),  # co_consts
        _tuple([_short_ascii(name) for name in names]),  # co_names
        _tuple([_short_ascii("x")]),  # co_varnames
        _tuple([]),  # co_freevars
        _tuple([]),  # co_cellvars
        _short_ascii("model.py"),  # co_filename
        _short_ascii("<lambda>"),  # co_name
        _long(57),  # co_firstlineno
        _bytes(b"\x00\x01"),  # co_lnotab
    ])


def this_python_lambda_code() -> bytes:
    """The same Lambda marshalled by the running Python (a file whose code does run here)."""
    return marshal.dumps((lambda x: x / 255.0 - 0.5).__code__)


# --------------------------------------------------------------------------- Keras 2 files


def _keras2_layer_configs(lambda_code: bytes) -> list[dict]:
    glorot = {"class_name": "VarianceScaling",
              "config": {"scale": 1.0, "mode": "fan_avg", "distribution": "uniform", "seed": None}}
    zeros = {"class_name": "Zeros", "config": {}}
    common = {"kernel_initializer": glorot, "bias_initializer": zeros, "kernel_regularizer": None,
              "bias_regularizer": None, "activity_regularizer": None, "kernel_constraint": None,
              "bias_constraint": None}
    configs = [
        {"class_name": "Lambda", "config": {
            "name": "lambda_1", "trainable": True, "batch_input_shape": [None, *INPUT_SHAPE],
            "dtype": "float32",
            "function": [base64.b64encode(lambda_code).decode("ascii"), None, None],
            "function_type": "lambda", "output_shape": None, "output_shape_type": "raw",
            "arguments": {}}},
        {"class_name": "Cropping2D", "config": {
            "name": "cropping2d_1", "trainable": True, "cropping": [list(c) for c in CROPPING],
            "data_format": "channels_last"}},
    ]
    for index, (filters, size, stride) in enumerate(CONVOLUTIONS, start=1):
        configs.append({"class_name": "Conv2D", "config": {
            "name": f"conv2d_{index}", "trainable": True, "filters": filters,
            "kernel_size": [size, size], "strides": [stride, stride], "padding": "valid",
            "data_format": "channels_last", "dilation_rate": [1, 1], "activation": "relu",
            "use_bias": True, **common}})
    configs.append({"class_name": "Flatten", "config": {
        "name": "flatten_1", "trainable": True, "data_format": "channels_last"}})
    for index, units in enumerate(DENSE, start=1):
        configs.append({"class_name": "Dense", "config": {
            "name": f"dense_{index}", "trainable": True, "units": units, "activation": "linear",
            "use_bias": True, **common}})
    return configs


def _write_weights(handle: h5py.File, model: keras.Model, weight_names) -> None:
    group = handle.create_group("model_weights")
    names = [layer.name for layer in model.layers]
    group.attrs["layer_names"] = np.array([name.encode() for name in names])
    group.attrs["backend"] = b"tensorflow"
    group.attrs["keras_version"] = handle.attrs["keras_version"]
    for layer in model.layers:
        layer_group = group.create_group(layer.name)
        stored = weight_names(layer)
        layer_group.attrs["weight_names"] = np.array([name.encode() for name in stored])
        for name, array in zip(stored, layer.get_weights(), strict=True):
            layer_group.create_dataset(name, data=array)


def write_keras2_h5(path: Path, model: keras.Model, *, lambda_code: bytes | None = None) -> Path:
    """``model`` (a :func:`student_model`) as Keras 2.2.4 on Python 3.6 saved it."""
    code = python36_lambda_code() if lambda_code is None else lambda_code
    config = {"class_name": "Sequential",
              "config": {"name": "sequential_1", "layers": _keras2_layer_configs(code)}}
    with h5py.File(path, "w") as handle:
        handle.attrs["keras_version"] = b"2.2.4"
        handle.attrs["backend"] = b"tensorflow"
        handle.attrs["model_config"] = json.dumps(config).encode("utf-8")
        kinds = {"Conv2D": ("kernel", "bias"), "Dense": ("kernel", "bias")}

        def weight_names(layer):
            parts = kinds.get(type(layer).__name__, ())
            return [f"{layer.name}/{part}:0" for part in parts]

        _write_weights(handle, model, weight_names)
    return path


def write_keras1_h5(path: Path, model: keras.Model) -> Path:
    """``model`` as Keras 1.2.1 saved it (Keras 1 configs and weight names)."""
    code = python36_lambda_code()
    configs = [
        {"class_name": "Lambda", "config": {
            "name": "lambda_1", "trainable": True, "batch_input_shape": [None, *INPUT_SHAPE],
            "input_dtype": "float32", "function": code.decode("raw_unicode_escape"),
            "function_type": "lambda", "output_shape": None, "output_shape_type": "raw",
            "arguments": {}}},
        {"class_name": "Cropping2D", "config": {
            "name": "cropping2d_1", "trainable": True, "cropping": [list(c) for c in CROPPING],
            "dim_ordering": "tf"}},
    ]
    for index, (filters, size, stride) in enumerate(CONVOLUTIONS, start=1):
        configs.append({"class_name": "Convolution2D", "config": {
            "name": f"convolution2d_{index}", "trainable": True, "nb_filter": filters,
            "nb_row": size, "nb_col": size, "subsample": [stride, stride],
            "border_mode": "valid", "dim_ordering": "tf", "activation": "relu", "bias": True,
            "init": "glorot_uniform", "W_regularizer": None, "b_regularizer": None}})
    configs.append({"class_name": "Flatten", "config": {"name": "flatten_1", "trainable": True}})
    for index, units in enumerate(DENSE, start=1):
        configs.append({"class_name": "Dense", "config": {
            "name": f"dense_{index}", "trainable": True, "output_dim": units,
            "activation": "linear", "bias": True, "init": "glorot_uniform"}})
    renamed = {f"conv2d_{index}": f"convolution2d_{index}"
               for index in range(1, len(CONVOLUTIONS) + 1)}
    with h5py.File(path, "w") as handle:
        handle.attrs["keras_version"] = b"1.2.1"
        handle.attrs["model_config"] = json.dumps(
            {"class_name": "Sequential", "config": configs}).encode("utf-8")

        group = handle.create_group("model_weights")
        names = [renamed.get(layer.name, layer.name) for layer in model.layers]
        group.attrs["layer_names"] = np.array([name.encode() for name in names])
        for layer, name in zip(model.layers, names, strict=True):
            layer_group = group.create_group(name)
            arrays = layer.get_weights()
            stored = [f"{name}_{part}" for part in ("W", "b")][: len(arrays)]
            layer_group.attrs["weight_names"] = np.array([item.encode() for item in stored])
            for item, array in zip(stored, arrays, strict=True):
                layer_group.create_dataset(item, data=array)
    return path
