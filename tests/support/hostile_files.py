"""Hostile inputs that are small on disk and huge once read: model files whose configuration
declares enormous layers or whose weights inflate, and driving logs of millions of short rows.
Shared by the tests and by ``benchmarks/faults_round3_bounds.py`` (one definition of each
probe's input)."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

#: Bytes of zeros written per call while inflating a zip member (keeps the maker's memory small).
_CHUNK_BYTES = 16 << 20
#: The member of a ``.keras`` archive that holds the weights.
WEIGHTS_MEMBER = "model.weights.h5"


def keras_with_huge_dense(source: Path, dest: Path, units: int) -> Path:
    """A copy of the ``.keras`` file ``source`` whose last ``Dense`` layer declares ``units``
    outputs: the archive stays a few KB, the weights Keras would allocate do not."""

    def change(layers: list[dict]) -> None:
        [layer for layer in layers if layer["class_name"] == "Dense"][-1]["config"]["units"] = units

    return _keras_with_layers(source, dest, change)


def keras_with_input_shape(source: Path, dest: Path, shape: list[int | None]) -> Path:
    """A copy of the ``.keras`` file ``source`` whose input layer declares ``shape``."""

    def change(layers: list[dict]) -> None:
        layers[0]["config"]["batch_shape"] = shape

    return _keras_with_layers(source, dest, change)


def _keras_with_layers(source: Path, dest: Path, change) -> Path:
    with zipfile.ZipFile(source) as archive:
        members = {info.filename: archive.read(info) for info in archive.infolist()}
    config = json.loads(members["config.json"])
    change(config["config"]["layers"])
    members["config.json"] = json.dumps(config).encode("utf-8")
    with zipfile.ZipFile(dest, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return dest


def h5_with_huge_dense(source: Path, dest: Path, units: int) -> Path:
    """A copy of the ``.h5`` model file ``source`` (Keras 1, 2 or 3) whose last ``Dense`` layer
    declares ``units`` outputs in its ``model_config``; the stored weights stay as they were."""
    import h5py

    shutil.copy(source, dest)
    with h5py.File(dest, "a") as handle:
        config = json.loads(handle.attrs["model_config"])
        dense = [layer for layer in config["config"]["layers"] if layer["class_name"] == "Dense"]
        dense[-1]["config"]["units"] = units
        handle.attrs["model_config"] = json.dumps(config).encode("utf-8")
    return dest


def keras_with_inflating_weights(source: Path, dest: Path, inflated_bytes: int) -> Path:
    """A copy of the ``.keras`` file ``source`` whose weights member is ``inflated_bytes`` of
    zeros, deflated: about a thousandth of that on disk."""
    with zipfile.ZipFile(source) as archive:
        members = {info.filename: archive.read(info) for info in archive.infolist()
                   if info.filename != WEIGHTS_MEMBER}
    with zipfile.ZipFile(dest, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
        with archive.open(WEIGHTS_MEMBER, "w", force_zip64=True) as member:
            chunk = bytes(_CHUNK_BYTES)
            left = inflated_bytes
            while left > 0:
                member.write(chunk[:left])
                left -= len(chunk)
    return dest


def log_of_many_rows(folder: Path, rows: int, images: Path) -> Path:
    """A recording in ``folder``: three real images (copied from the folder ``images``) and a
    ``driving_log.csv`` of ``rows`` short rows that all use them -- every row valid."""
    image_folder = folder / "IMG"
    image_folder.mkdir(parents=True, exist_ok=True)
    first = sorted(images.glob("center_*.jpg"))[0]
    for camera in ("c", "l", "r"):
        shutil.copy(first, image_folder / f"{camera}.jpg")
    line = b"c.jpg,l.jpg,r.jpg,0.1,0.5,0,9\n"
    block = line * 65536
    with open(folder / "driving_log.csv", "wb") as handle:
        left = rows
        while left > 0:
            count = min(left, 65536)
            handle.write(block if count == 65536 else line * count)
            left -= count
    return folder
