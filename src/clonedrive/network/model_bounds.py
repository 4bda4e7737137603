"""How much memory a model file will ask for, checked before Keras allocates any of it.

A model file is small on disk, and what it asks for is not: a ``.keras`` archive can hold a
weights member of zeros that inflates a thousandfold, an HDF5 dataset can be compressed the
same way, and the layer configuration can declare a ``Dense`` layer of a hundred million units,
whose weights Keras allocates while it builds the network -- before it reads a single stored
weight. Four checks, in the order :func:`clonedrive.network.model_file.read_model` makes them:

1. :func:`check_archive`: the zip members' declared unpacked sizes (from the archive's central
   directory; Python's ``zipfile`` never yields more than that) against
   :data:`MAX_UNPACKED_BYTES`, and each large member against :data:`MAX_PACKING_RATIO`.
2. :func:`stored_weight_bytes`: the weights the file stores, as HDF5 dataset shapes (metadata
   only, nothing is read), checked the same way: these are what loading reads into memory.
3. :func:`check_declared_shapes`: no tensor shape in the configuration holds more than
   :data:`MAX_SAMPLE_VALUES` values a sample (Keras traces some layers with real tensors).
4. :func:`declared_weight_bytes` and :func:`check_declared`: the network built from its
   configuration inside a ``keras.StatelessScope``, where Keras creates each variable with its
   shape but without its value (deferred initialisation), so that counting what the
   configuration declares costs nothing. A file declaring more than it stores is refused: its
   weights could never load, and building it would fill the memory first.
"""

from __future__ import annotations

import math
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from clonedrive.network.errors import ModelFileError

#: The most a model file may unpack to [bytes]: all members of a ``.keras`` archive together,
#: and all weights of an HDF5 file. NVIDIA's network is 1 MB of weights; the largest student
#: networks are a few hundred MB.
MAX_UNPACKED_BYTES = 1 << 30
#: Unpacked / packed size above which a large member is a decompression bomb, not a model:
#: Keras stores its members unpacked (ratio 1) and trained float weights barely compress.
MAX_PACKING_RATIO = 100
#: Members (and HDF5 files) smaller than this unpacked are not held to the ratio [bytes].
RATIO_FLOOR_BYTES = 16 << 20
#: What a configuration may declare beyond the weights stored [bytes]: random-seed states and
#: other small variables a file need not store.
DECLARED_SLACK_BYTES = 1 << 20
#: The member of a ``.keras`` archive that holds the weights (Keras's name).
WEIGHTS_MEMBER = "model.weights.h5"
#: Values one sample's tensor may declare (a camera frame is 160 x 320 x 3 = 153,600): Keras
#: traces shapes with real tensors of the declared size where a layer cannot be traced
#: without them.
MAX_SAMPLE_VALUES = 1 << 26
#: Configuration keys whose value is a tensor's shape.
SHAPE_KEYS = ("batch_shape", "batch_input_shape", "input_shape", "shape")


class ModelBoundsError(ModelFileError):
    """A model file that would ask for more memory than it can hold; names the file."""


def _size(size: int) -> str:
    """``size`` [bytes] in the largest binary unit it fills: "5.1 GiB", "21.8 KiB"."""
    for unit, shift in (("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if size >= 1 << shift:
            return f"{size / (1 << shift):.1f} {unit}"
    return f"{size} bytes"


def check_archive(path: Path, archive: zipfile.ZipFile) -> None:
    """Refuse a ``.keras`` archive whose members unpack past :data:`MAX_UNPACKED_BYTES`
    together, or one of which is packed more than :data:`MAX_PACKING_RATIO` to one."""
    members = archive.infolist()
    unpacked = sum(info.file_size for info in members)
    if unpacked > MAX_UNPACKED_BYTES:
        raise ModelBoundsError(
            f"{path}: its members unpack to {_size(unpacked)}, over the "
            f"{_size(MAX_UNPACKED_BYTES)} limit for a model file; not loaded")
    for info in members:
        _check_ratio(path, info.filename, info.file_size, info.compress_size)


def _check_ratio(path: Path, what: str, unpacked: int, packed: int) -> None:
    if unpacked > RATIO_FLOOR_BYTES and unpacked > MAX_PACKING_RATIO * max(packed, 1):
        raise ModelBoundsError(
            f"{path}: {what}: {_size(unpacked)} unpacked from {_size(packed)} on disk, more "
            f"than {MAX_PACKING_RATIO} to 1 (the limit for a model file); not loaded")


def stored_weight_bytes(path: Path, source: Any, packed: int) -> int:
    """Bytes of all HDF5 datasets in ``source`` (a path or an open binary file: the weights
    member of an archive), from their shapes; refused past :data:`MAX_UNPACKED_BYTES`, or past
    :data:`MAX_PACKING_RATIO` x ``packed`` (the HDF5 file's size on disk)."""
    import h5py

    sizes: list[int] = []

    def visit(name: str, item: Any) -> None:
        if isinstance(item, h5py.Dataset) and item.shape is not None:
            sizes.append(math.prod(item.shape) * item.dtype.itemsize)

    try:
        with h5py.File(source, "r") as handle:
            handle.visititems(visit)
    except (OSError, ValueError) as error:
        raise ModelBoundsError(f"{path}: the weights are not readable HDF5 ({error})") from None
    stored = sum(sizes)
    if stored > MAX_UNPACKED_BYTES:
        raise ModelBoundsError(
            f"{path}: its weights are {_size(stored)}, over the {_size(MAX_UNPACKED_BYTES)} "
            "limit for a model file; not loaded")
    _check_ratio(path, "its weights", stored, packed)
    return stored


def check_declared_shapes(path: Path, config: Any) -> None:
    """Refuse a configuration that declares a tensor shape of more than
    :data:`MAX_SAMPLE_VALUES` values per sample (any list of whole numbers under one of
    :data:`SHAPE_KEYS`, the batch's ``None`` left out), before anything is built."""
    stack = [config]
    while stack:
        node = stack.pop()
        if isinstance(node, list):
            stack.extend(node)
        if not isinstance(node, dict):
            continue
        for key, value in node.items():
            sizes = [size for size in value if isinstance(size, int)] if isinstance(
                value, list) and key in SHAPE_KEYS else []
            if sizes and math.prod(max(size, 0) for size in sizes) > MAX_SAMPLE_VALUES:
                raise ModelBoundsError(
                    f"{path}: its layer configuration declares a tensor of shape {value} "
                    f"({math.prod(sizes):,} values a sample); the limit is "
                    f"{MAX_SAMPLE_VALUES:,}; not loaded")
            stack.append(value)


def declared_weight_bytes(build: Callable[[], Any]) -> int:
    """Bytes of the variables of the network ``build()`` makes, made without allocating them.

    Inside ``keras.StatelessScope(initialize_variables=False)`` Keras gives each new variable
    its shape and defers its value. Keras also lists such variables, to initialise them when a
    later top-level stateless scope closes; that list (Keras internals: ``global_state``, no
    public access) is put back as it was, so the network built here is never allocated.
    """
    import numpy as np

    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()  # first: it chooses the backend, which Keras reads on import
    from keras.src.backend.common import global_state

    key = "uninitialized_variables"
    before = list(global_state.get_global_attribute(key, None) or [])
    try:
        with keras.StatelessScope(initialize_variables=False):
            network = build()
        return sum(math.prod(variable.shape) * np.dtype(variable.dtype).itemsize
                   for variable in network.weights)
    finally:
        global_state.set_global_attribute(key, before)


def check_declared(path: Path, declared: int, stored: int) -> None:
    """Refuse a file whose configuration declares more weights than it stores."""
    if declared > stored + DECLARED_SLACK_BYTES:
        raise ModelBoundsError(
            f"{path}: its layer configuration declares {_size(declared)} of weights but the file "
            f"stores {_size(stored)} (limit {_size(MAX_UNPACKED_BYTES)}); not loaded")


# --------------------------------------------------------------------------- building unallocated


def keras_archive_network(config: dict, *, safe_mode: bool) -> Callable[[], Any]:
    """What ``keras.models.load_model(compile=False)`` builds from a ``.keras`` archive's
    ``config.json``, as a function for :func:`declared_weight_bytes`."""

    def build() -> Any:
        from clonedrive.base.keras_backend import import_keras

        keras = import_keras()
        return keras.saving.deserialize_keras_object(
            {**config, "compile_config": None}, safe_mode=safe_mode)

    return build


def keras_h5_network(config: dict, *, safe_mode: bool) -> Callable[[], Any]:
    """What Keras's HDF5 loader builds from an ``.h5`` file's ``model_config`` (the same calls,
    Keras internals: there is no public way to build from a Keras 2 configuration)."""

    def build() -> Any:
        import json

        from keras.src.legacy.saving import json_utils, saving_options, saving_utils
        from keras.src.saving import serialization_lib

        decoded = json_utils.decode(json.dumps(config))
        with saving_options.keras_option_scope(use_legacy_config=True), \
                serialization_lib.SafeModeScope(safe_mode):
            return saving_utils.model_from_config(decoded)

    return build
