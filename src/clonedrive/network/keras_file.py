"""A Keras model file read at the lowest level: its kind, its layer configuration, Keras's loader.

:func:`file_kind` tells a ``.keras`` archive from an HDF5 file by its first bytes,
:func:`model_config` reads the layer configuration (and the Keras version that saved it) as JSON
without building anything, :func:`lambda_layer_names` finds the ``Lambda`` layers in it, and
:func:`keras_load` is ``keras.models.load_model`` with its errors as
:class:`~clonedrive.network.errors.ModelFileError`. :mod:`clonedrive.network.model_file` (every
check before loading) and :mod:`clonedrive.network.legacy_keras` (students' Keras 1/2 files) both
build on these.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

from clonedrive.network.errors import ModelFileError, one_line

#: The JSON layer configuration inside a model file (a few tens of KB in practice).
MAX_CONFIG_BYTES = 16 << 20

ZIP_SIGNATURE = b"PK\x03\x04"
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: HDF5 allows a user block before the superblock: the signature is at 0, 512, 1024, 2048, ...
_HDF5_OFFSETS = (0, 512, 1024, 2048, 4096)


def file_kind(path: Path) -> str:
    """``"zip"`` (a .keras archive), ``"hdf5"`` or ``"other"``, from the file's first bytes."""
    with open(path, "rb") as handle:
        head = handle.read(max(_HDF5_OFFSETS) + len(HDF5_SIGNATURE))
    if head.startswith(ZIP_SIGNATURE):
        return "zip"
    if any(head[offset : offset + 8] == HDF5_SIGNATURE for offset in _HDF5_OFFSETS):
        return "hdf5"
    return "other"


def keras_load(path: Path, *, safe_mode: bool) -> Any:
    """``keras.models.load_model`` for inference, its errors as :class:`ModelFileError`."""
    from clonedrive.base.keras_backend import import_keras

    keras = import_keras()
    try:
        return keras.models.load_model(path, compile=False, safe_mode=safe_mode)
    except (ValueError, TypeError, OSError, KeyError, AttributeError, IndexError,
            RecursionError, zipfile.BadZipFile) as error:
        raise ModelFileError(f"{path}: cannot load the model: {one_line(error)}") from None


def model_config(path: Path, kind: str) -> tuple[dict, str | None]:
    """``(the model's layer configuration, the Keras version that saved it or None)``, read as
    JSON without building anything."""
    if kind == "zip":
        text, version = _zip_config(path)
    else:
        text, version = _hdf5_config(path)
    try:
        config = json.loads(text)
    except (ValueError, RecursionError) as error:
        raise ModelFileError(f"{path}: the model configuration is not JSON ({error})") from None
    if not isinstance(config, dict):
        raise ModelFileError(f"{path}: the model configuration is not a JSON object")
    return config, version


def _zip_config(path: Path) -> tuple[str, str | None]:
    from clonedrive.network.model_bounds import check_archive

    try:
        with zipfile.ZipFile(path) as archive:
            check_archive(path, archive)
            names = set(archive.namelist())
            if "config.json" not in names:
                raise ModelFileError(
                    f"{path}: not a Keras model file (a zip archive without config.json)"
                )
            text = _zip_member(archive, "config.json", path)
            version = None
            if "metadata.json" in names:
                try:
                    metadata = json.loads(_zip_member(archive, "metadata.json", path))
                    version = str(metadata.get("keras_version")) if isinstance(
                        metadata, dict) else None
                except ValueError:
                    version = None
            return text, version
    except zipfile.BadZipFile as error:
        raise ModelFileError(f"{path}: not a Keras model file (broken zip: {error})") from None


def _zip_member(archive: zipfile.ZipFile, name: str, path: Path) -> str:
    info = archive.getinfo(name)
    if info.file_size > MAX_CONFIG_BYTES:
        raise ModelFileError(
            f"{path}: {name} is {info.file_size} bytes, over the {MAX_CONFIG_BYTES} byte limit"
        )
    with archive.open(info) as member:
        data = member.read(MAX_CONFIG_BYTES + 1)
    if len(data) > MAX_CONFIG_BYTES:
        raise ModelFileError(f"{path}: {name} is over the {MAX_CONFIG_BYTES} byte limit")
    return data.decode("utf-8", errors="replace")


def _hdf5_config(path: Path) -> tuple[str, str | None]:
    import h5py

    try:
        with h5py.File(path, "r") as handle:
            raw = handle.attrs.get("model_config")
            version = handle.attrs.get("keras_version")
    except OSError as error:
        raise ModelFileError(f"{path}: not a readable HDF5 model file ({error})") from None
    if raw is None:
        raise ModelFileError(
            f"{path}: an HDF5 file without a model configuration (weights only?). Save the "
            "whole model (model.save), or build the network in Python and call "
            "model.load_weights on this file"
        )
    if isinstance(raw, bytes):
        raw = raw.decode("utf-8", errors="replace")
    if isinstance(version, bytes):
        version = version.decode("ascii", errors="replace")
    text = str(raw)
    if len(text) > MAX_CONFIG_BYTES:
        raise ModelFileError(f"{path}: the model configuration is over {MAX_CONFIG_BYTES} bytes")
    return text, None if version is None else str(version)


def lambda_layer_names(config: Any) -> list[str]:
    """Names of the ``Lambda`` layers anywhere in a model configuration (Keras 1, 2 or 3)."""
    names: list[str] = []
    stack = [config]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            if node.get("class_name") == "Lambda":
                layer = node.get("config")
                name = layer.get("name") if isinstance(layer, dict) else None
                names.append(str(name) if name is not None else "unnamed")
            stack.extend(reversed(list(node.values())))
        elif isinstance(node, list):
            stack.extend(reversed(node))
    return names
