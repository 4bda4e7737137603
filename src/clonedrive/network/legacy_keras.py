"""Students' Keras 1 and Keras 2 ``.h5`` models on Keras 3.

Most Udacity students' models (2017-2020) are ``Sequential`` nets saved by Keras 1.2 or 2.x:
``Lambda(lambda x: x / 255.0 - 0.5)``, ``Cropping2D``, ``Conv2D`` (``Convolution2D`` in Keras 1),
``Dropout``, ``Flatten``, ``Dense`` -- NVIDIA's net or a smaller one. Keras 3 reads these files,
but a ``Lambda`` holds the *bytecode* of the Python that saved it (3.5-3.8), and Python 3.11
cannot run that: ``marshal`` fails, or worse, loads garbage.

:func:`load` (used by :func:`clonedrive.network.model_file.read_model` for a legacy ``.h5``):

1. without Lambda layers: Keras 3's own loader;
2. with Lambda layers (only under ``--trust-model``): the Lambda code is first run on a small
   array in a separate Python process (:func:`probe_lambdas`; a crash there cannot take this
   process down). If it runs, Keras 3 loads the file with safe mode off. (Keras 3.15 cannot
   load a Keras 2 ``Sequential`` whose first layer carries ``batch_input_shape``, which is how
   Keras 2 saved them all, so in practice step 3 follows);
3. otherwise -- or if Keras 3 refuses the file -- :func:`rebuild`: the network is built again
   from its layer list (the JSON in the file; no stored code runs), each Lambda replaced by the
   ``Rescaling`` layer it computes, and the weights are loaded by layer name.

A Lambda is recognised from the constants in its bytecode (:data:`NORMALISATIONS`: ``x / 255 -
0.5``, ``x / 127.5 - 1``, ``x / 128 - 1``, ``x / 255``); one that calls anything (resizing,
colour conversion: ``tf``, ``K``, ``resize``...) is not rebuilt. The way out then, documented
in docs/udacity.md: rebuild the network in Python with built-in layers (``Rescaling``, ``Resizing``)
and the same layer names, and call :func:`rebuild` with ``normalisation=(scale, offset)``, or
load the weights into your own model with ``load_weights_by_name``.
"""

from __future__ import annotations

import base64
import binascii
import json
import logging
import re
import struct
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from clonedrive.network.errors import ModelFileError
from clonedrive.network.keras_file import keras_load, model_config

logger = logging.getLogger("clonedrive.model")

#: (constants the Lambda's code must hold, scale, offset, formula), most specific first.
NORMALISATIONS: tuple[tuple[tuple[float, ...], float, float, str], ...] = (
    ((255.0, 0.5), 1.0 / 255.0, -0.5, "x / 255 - 0.5"),
    ((127.5, 1.0), 1.0 / 127.5, -1.0, "x / 127.5 - 1"),
    ((128.0, 1.0), 1.0 / 128.0, -1.0, "x / 128 - 1"),
    ((255.0,), 1.0 / 255.0, 0.0, "x / 255"),
)
#: Names in a Lambda's code that mean it does more than scale pixel values (whole words).
_CALLS = frozenset({
    "tf", "ktf", "K", "backend", "keras", "np", "numpy", "cv2", "image", "resize", "cvtColor",
    "reshape", "mean", "std", "cast", "ops", "slice", "crop", "concatenate", "expand_dims",
    "stack", "tile", "sqrt", "square", "abs", "clip", "maximum", "minimum", "transpose",
})
_PROBE_TIMEOUT_S = 30.0

#: A Python program run in a child process: load each Lambda's code and call it on an array.
_PROBE = r"""
import base64, binascii, json, marshal, sys, types
import numpy as np
for text in json.load(sys.stdin):
    try:
        raw = base64.b64decode(text.encode("ascii"), validate=True)
    except (binascii.Error, ValueError, UnicodeEncodeError):
        raw = text.encode("raw_unicode_escape")
    code = marshal.loads(raw)
    function = types.FunctionType(code, {"__builtins__": __builtins__})
    sample = np.full((1, 4, 6, 3), 128.0, dtype=np.float32)
    result = np.asarray(function(sample))
    if result.shape != sample.shape or not np.all(np.isfinite(result)):
        raise SystemExit(f"the Lambda gives {result.shape}, not an array shaped like its input")
print("ok")
"""


def is_legacy_version(version: str | None) -> bool:
    """Whether a ``keras_version`` attribute names Keras 1 or 2 (or is missing: Keras 1.0)."""
    return version is None or version.strip().startswith(("1.", "2."))


def load(path: Path, config: dict, *, lambdas: list[str]) -> Any:
    """A Keras 3 model for a Keras 1/2 ``.h5`` file; see the module doc for the steps."""
    if lambdas:
        problem = probe_lambdas(config)
        if problem is not None:
            logger.warning(
                "%s: its Lambda code does not run on Python %d.%d (%s); rebuilding the network "
                "from its layer list without running it", path, *sys.version_info[:2], problem)
            return rebuild(path, config)
    try:
        return keras_load(path, safe_mode=not lambdas)
    except ModelFileError as error:
        native = error
    try:
        model = rebuild(path, config)
    except ModelFileError as error:
        raise ModelFileError(f"{native}; rebuilding it from its layer list failed too: "
                             f"{str(error).removeprefix(f'{path}: ')}") from None
    logger.warning("%s: Keras 3 could not load it as saved (%s); rebuilt it from its layer "
                   "list", path, native)
    return model


# --------------------------------------------------------------------------- Lambda code


def _lambda_code_texts(config: Any) -> list[tuple[str, str]]:
    """``(layer name, stored code text)`` of every Lambda in a Keras 1/2 configuration."""
    found = []
    stack = [config]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            if node.get("class_name") == "Lambda" and isinstance(node.get("config"), dict):
                layer = node["config"]
                function = layer.get("function")
                if isinstance(function, list) and function:  # Keras 2: [code, defaults, closure]
                    function = function[0]
                if isinstance(function, dict):  # Keras 3 style {"class_name": "__lambda__"}
                    function = (function.get("config") or {}).get("code")
                found.append((str(layer.get("name")), function if isinstance(function, str)
                              else ""))
            stack.extend(node.values())
        elif isinstance(node, list):
            stack.extend(node)
    return found


def probe_lambdas(config: dict) -> str | None:
    """None if every Lambda's stored code runs on this Python (tried in a child process on a
    small array), else why not, in a few words."""
    texts = [text for _, text in _lambda_code_texts(config)]
    if not all(texts):
        return "a Lambda stores no code"
    try:
        result = subprocess.run(
            [sys.executable, "-I", "-c", _PROBE], input=json.dumps(texts), text=True,
            capture_output=True, timeout=_PROBE_TIMEOUT_S, check=False,
        )
    except (OSError, subprocess.TimeoutExpired) as error:
        return f"trying it failed: {error}"
    if result.returncode == 0 and result.stdout.strip().endswith("ok"):
        return None
    if result.returncode < 0:
        return f"trying it crashed the Python process (signal {-result.returncode})"
    lines = [line for line in result.stderr.strip().splitlines() if line.strip()]
    return lines[-1].strip() if lines else f"exit status {result.returncode}"


def _code_bytes(text: str) -> bytes:
    try:
        return base64.b64decode(text.encode("ascii"), validate=True)
    except (binascii.Error, ValueError, UnicodeEncodeError):
        return text.encode("raw_unicode_escape")


def code_constants(raw: bytes) -> set[float]:
    """Numbers stored as constants in marshalled bytecode (any Python 3 version): binary floats
    (``g``) and 32-bit ints (``i``), with or without marshal's reference flag."""
    values: set[float] = set()
    for position, byte in enumerate(raw):
        kind = byte & 0x7F
        if kind == ord("g") and position + 9 <= len(raw):
            value = struct.unpack_from("<d", raw, position + 1)[0]
        elif kind == ord("i") and position + 5 <= len(raw):
            value = float(struct.unpack_from("<i", raw, position + 1)[0])
        else:
            continue
        if np.isfinite(value):
            values.add(value)
    return values


_IDENTIFIER = re.compile(rb"[A-Za-z_][A-Za-z0-9_]*")


def code_strings(raw: bytes) -> set[str]:
    """Identifier-like strings stored in marshalled bytecode (the code's names, argument names,
    function and file names): marshal's short strings (``z``/``Z``, one length byte) and
    strings (``a``/``A``/``u``/``t``, four length bytes), with or without the reference flag."""
    found: set[str] = set()
    for position, byte in enumerate(raw):
        kind = chr(byte & 0x7F)
        if kind in "zZ" and position + 2 <= len(raw):
            start, length = position + 2, raw[position + 1]
        elif kind in "aAut" and position + 5 <= len(raw):
            start, length = position + 5, struct.unpack_from("<i", raw, position + 1)[0]
        else:
            continue
        if 0 < length <= 64 and start + length <= len(raw):
            word = raw[start : start + length]
            if _IDENTIFIER.fullmatch(word):
                found.add(word.decode("ascii"))
    return found


def lambda_normalisation(name: str, text: str, path: Path) -> tuple[float, float, str]:
    """``(scale, offset, formula)`` of the pixel scaling a stored Lambda computes, read from its
    bytecode's constants; :class:`ModelFileError` when it is not a recognised one."""
    raw = _code_bytes(text)
    names = {word for word in code_strings(raw)
             if word in _CALLS or "resize" in word.lower() or "rgb_to" in word.lower()}
    if names:
        raise ModelFileError(
            f"{path}: Lambda {name!r} uses {', '.join(sorted(names))}: it does more than scale "
            "pixels, so it cannot be rebuilt without running its code (see docs/udacity.md, "
            "'Students' models', for the way out)"
        )
    constants = code_constants(raw)
    for needed, scale, offset, formula in NORMALISATIONS:
        if all(any(abs(value - want) < 1e-9 for value in constants) for want in needed):
            return scale, offset, formula
    raise ModelFileError(
        f"{path}: Lambda {name!r} is not a recognised normalisation (looked for "
        f"{'; '.join(item[3] for item in NORMALISATIONS)}), so it cannot be rebuilt without "
        "running its code (see docs/udacity.md, 'Students' models', for the way out)"
    )


# --------------------------------------------------------------------------- rebuilding


def rebuild(path: str | Path, config: dict | None = None, *,
            normalisation: tuple[float, float] | None = None) -> Any:
    """The network of a Keras 1/2 ``Sequential`` ``.h5`` file, built with Keras 3 layers
    without running stored code, with the file's weights loaded by layer name.

    ``normalisation=(scale, offset)`` replaces every Lambda by ``Rescaling(scale, offset)``
    instead of recognising it from its bytecode (the way out for an unrecognised one).
    """
    path = Path(path)
    if config is None:
        config, _ = model_config(path, "hdf5")
    model, replaced = rebuilt_network(path, config, normalisation=normalisation)
    loaded = load_weights_by_name(model, path)
    logger.warning(
        "%s: rebuilt from its layer list without running stored code: %s; weights of %d "
        "layers loaded by name", path, "; ".join(replaced) or "no Lambda layers", loaded)
    return model


def rebuilt_network(path: Path, config: dict, *,
                    normalisation: tuple[float, float] | None = None) -> tuple[Any, list[str]]:
    """(the network :func:`rebuild` makes, before its weights are loaded; the Lambda layers
    it replaced, described)."""
    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()
    layer_configs, model_name = _sequential_layers(config, path)
    input_shape = None
    built = []
    replaced = []
    for entry in layer_configs:
        if not isinstance(entry, dict) or not isinstance(entry.get("config"), dict):
            raise ModelFileError(f"{path}: a layer entry is not a {{class_name, config}} object")
        class_name, settings = str(entry.get("class_name")), entry["config"]
        shape = settings.get("batch_input_shape") or settings.get("batch_shape")
        if input_shape is None and isinstance(shape, list) and len(shape) > 1:
            input_shape = tuple(shape[1:])
        if class_name == "InputLayer":
            continue
        if class_name == "Lambda":
            name = str(settings.get("name"))
            if normalisation is not None:
                scale, offset = normalisation
                formula = f"x * {scale:g} + {offset:g}"
            else:
                text = dict(_lambda_code_texts(entry)).get(name, "")
                scale, offset, formula = lambda_normalisation(name, text, path)
            built.append(keras.layers.Rescaling(scale, offset=offset, name=name))
            replaced.append(f"{name} -> Rescaling ({formula})")
            continue
        built.append(_build_layer(keras, class_name, settings, path))
    if input_shape is None:
        raise ModelFileError(f"{path}: the first layer has no input shape (batch_input_shape)")
    inputs = keras.Input(shape=input_shape, name="image_rgb")
    outputs = inputs
    for layer in built:
        outputs = layer(outputs)
    return keras.Model(inputs, outputs, name=model_name or "rebuilt"), replaced


def _sequential_layers(config: dict, path: Path) -> tuple[list, str | None]:
    class_name = config.get("class_name")
    body = config.get("config")
    if class_name != "Sequential":
        raise ModelFileError(
            f"{path}: a {class_name} model; only Sequential student models can be rebuilt "
            "(see docs/udacity.md, 'Students' models', for the way out)"
        )
    if isinstance(body, list):  # Keras 1 and early Keras 2
        return body, None
    if isinstance(body, dict) and isinstance(body.get("layers"), list):
        return body["layers"], body.get("name")
    raise ModelFileError(f"{path}: the Sequential configuration has no layer list")


def _pair(value: Any, default: Any = None) -> Any:
    if value is None:
        return default
    if isinstance(value, int | float):
        return (value, value)
    return tuple(tuple(item) if isinstance(item, list) else item for item in value)


def _build_layer(keras: Any, class_name: str, settings: dict, path: Path) -> Any:
    """A Keras 3 layer from a Keras 1/2 layer configuration (the layers students used)."""
    layers = keras.layers
    name = settings.get("name")
    data_format = settings.get("data_format", "channels_last")
    ordering = settings.get("dim_ordering", "tf")
    if data_format != "channels_last" or ordering not in ("tf", "default"):
        raise ModelFileError(
            f"{path}: layer {name!r} is channels-first ({data_format}, {ordering}); only "
            "channels-last (TensorFlow ordering) models can be rebuilt"
        )
    activation = settings.get("activation", "linear")
    padding = settings.get("padding", settings.get("border_mode", "valid"))
    use_bias = settings.get("use_bias", settings.get("bias", True))
    if class_name in ("Conv2D", "Convolution2D"):
        kernel = settings.get("kernel_size") or (settings.get("nb_row"), settings.get("nb_col"))
        return layers.Conv2D(
            int(settings.get("filters", settings.get("nb_filter"))), _pair(kernel),
            strides=_pair(settings.get("strides", settings.get("subsample")), (1, 1)),
            padding=padding, activation=activation, use_bias=bool(use_bias),
            dilation_rate=_pair(settings.get("dilation_rate"), (1, 1)), name=name,
        )
    if class_name == "Dense":
        return layers.Dense(int(settings.get("units", settings.get("output_dim"))),
                            activation=activation, use_bias=bool(use_bias), name=name)
    if class_name == "Cropping2D":
        return layers.Cropping2D(_pair(settings.get("cropping")), name=name)
    if class_name in ("MaxPooling2D", "AveragePooling2D"):
        pool = _pair(settings.get("pool_size"), (2, 2))
        strides = _pair(settings.get("strides"), None)
        layer = layers.MaxPooling2D if class_name == "MaxPooling2D" else layers.AveragePooling2D
        return layer(pool, strides=strides, padding=padding, name=name)
    if class_name == "Flatten":
        return layers.Flatten(name=name)
    if class_name in ("Dropout", "SpatialDropout2D"):
        rate = float(settings.get("rate", settings.get("p", 0.0)))
        layer = layers.Dropout if class_name == "Dropout" else layers.SpatialDropout2D
        return layer(rate, name=name)
    if class_name == "Activation":
        return layers.Activation(activation, name=name)
    if class_name == "ELU":
        return layers.ELU(alpha=float(settings.get("alpha", 1.0)), name=name)
    if class_name == "LeakyReLU":
        return layers.LeakyReLU(negative_slope=float(settings.get("alpha", 0.3)), name=name)
    if class_name == "ReLU":
        return layers.ReLU(name=name)
    if class_name == "BatchNormalization":
        axis = settings.get("axis", -1)
        axis = axis[0] if isinstance(axis, list) else axis
        return layers.BatchNormalization(
            axis=int(axis), epsilon=float(settings.get("epsilon", 1e-3)),
            center=bool(settings.get("center", True)), scale=bool(settings.get("scale", True)),
            name=name,
        )
    raise ModelFileError(
        f"{path}: layer {name!r} is a {class_name}, which the rebuilder does not know "
        "(it knows Lambda normalisation, Cropping2D, Conv2D, pooling, Dropout, Flatten, Dense, "
        "Activation, ELU, LeakyReLU, ReLU, BatchNormalization)"
    )


def load_weights_by_name(model: Any, path: str | Path) -> int:
    """Set the weights of every layer of ``model`` that has weights from the layer of the same
    name in a Keras 1/2 ``.h5`` file; returns how many layers were set."""
    import h5py

    path = Path(path)
    loaded = 0
    try:
        with h5py.File(path, "r") as handle:
            group = handle["model_weights"] if "model_weights" in handle else handle
            for layer in model.layers:
                wanted = layer.get_weights()
                if not wanted:
                    continue
                if layer.name not in group:
                    raise ModelFileError(f"{path}: no weights for layer {layer.name!r}")
                layer_group = group[layer.name]
                names = [item.decode() if isinstance(item, bytes) else str(item)
                         for item in layer_group.attrs.get("weight_names", [])]
                arrays = [np.asarray(layer_group[name]) for name in names]
                shapes = [array.shape for array in arrays]
                if shapes != [array.shape for array in wanted]:
                    raise ModelFileError(
                        f"{path}: layer {layer.name!r} stores weights of shapes {shapes}, the "
                        f"rebuilt layer needs {[array.shape for array in wanted]}"
                    )
                layer.set_weights(arrays)
                loaded += 1
    except (OSError, KeyError) as error:
        raise ModelFileError(f"{path}: cannot read the weights ({error})") from None
    return loaded
