"""Reading a steering-model file: ``.keras``, ``.h5`` (Keras 3, or a student's Keras 1/2) or ONNX.

:func:`load_model` is what every command uses: :func:`read_model`, then the model's inputs and
outputs checked (:func:`clonedrive.network.contract.check_model`). :func:`read_model` looks at
the file before handing it to Keras, so that each ordinary mistake gets one line naming the file:

* a file that is not a model: a ``.keras`` file is a zip archive holding ``config.json``, an
  ``.h5`` file starts with the HDF5 signature; anything else is "not a Keras model file" (Keras
  itself says "File not found" for a file that exists);
* a ``.keras`` file that is really HDF5, or the other way round (renamed files);
* a file larger than :data:`MAX_MODEL_BYTES`, or a config larger than
  :data:`~clonedrive.network.keras_file.MAX_CONFIG_BYTES`;
* a file that would take more memory than it holds -- members or weights that inflate, a
  configuration declaring more weights than the file stores -- checked before Keras allocates
  anything (:mod:`clonedrive.network.model_bounds`);
* ``Lambda`` layers (Python code stored in the file): refused unless ``trust`` (the
  ``--trust-model`` flag), which logs :data:`TRUST_WARNING`.

Students' models (2017-2020) are Keras 1 or 2 ``.h5`` files, most with
``Lambda(lambda x: x / 255.0 - 0.5)``. The Lambda's code is Python bytecode of the Python that
saved it (3.5-3.8), which Python 3.11 cannot run. With ``trust``, the code is first tried in a
separate process; if it does not run there, the network is rebuilt from its layer list without
running any stored code and the weights are loaded by layer name
(:mod:`clonedrive.network.legacy_keras`).

``runtime="onnx"`` (or a ``.onnx`` file) runs the model with ONNX Runtime
(:mod:`clonedrive.network.onnx_runtime`).
"""

from __future__ import annotations

import logging
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from clonedrive.network.contract import check_model
from clonedrive.network.errors import ModelFileError, one_line
from clonedrive.network.keras_file import file_kind, keras_load, lambda_layer_names, model_config

if TYPE_CHECKING:
    import keras

logger = logging.getLogger("clonedrive.model")

KERAS_SUFFIXES = (".keras", ".h5", ".hdf5")
ONNX_SUFFIX = ".onnx"
RUNTIMES = ("auto", "keras", "onnx")
#: Larger model files are refused before reading (a student's NVIDIA net is 1-400 MB).
MAX_MODEL_BYTES = 2 << 30

TRUST_WARNING = """\
WARNING: --trust-model: {path} has Lambda layers ({names}): Python code stored in the file.
WARNING: Keras safe mode is off for this file. Code in a model file runs with your rights:
WARNING: use this only for a model you made yourself or got from someone you trust."""


def load_model(
    path: str | Path, *, trust: bool = False, runtime: str = "auto"
) -> keras.Model:
    """Load a steering model for inference and check it
    (:func:`~clonedrive.network.contract.check_model`).

    ``path``: ``.keras``, ``.h5`` (Keras 3, or a student's Keras 1/2 file) or ``.onnx``.
    ``trust``: allow ``Lambda`` layers (Python code in the file; ``--trust-model``).
    ``runtime``: ``"auto"`` (ONNX Runtime for ``.onnx``, else Keras), ``"keras"`` or
    ``"onnx"`` (a Keras file is converted to ONNX in memory). Raises ``FileNotFoundError`` or
    ``ValueError`` with a one-line message naming the file.
    """
    model = read_model(path, trust=trust, runtime=runtime)
    try:
        check_model(model)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    return model


def read_model(path: str | Path, *, trust: bool = False, runtime: str = "auto") -> Any:
    """The model in ``path``, ready for ``predict_on_batch`` (a Keras model, or an
    :class:`~clonedrive.network.onnx_runtime.OnnxModel`). See the module doc.

    Raises ``FileNotFoundError`` (no such file) or :class:`ModelFileError`.
    """
    path = Path(path)
    if runtime not in RUNTIMES:
        raise ModelFileError(f"runtime {runtime!r}; expected one of: {', '.join(RUNTIMES)}")
    if not path.exists():
        raise FileNotFoundError(f"model file not found: {path}")
    if not path.is_file():
        raise ModelFileError(f"{path}: not a file (expected a .keras, .h5 or .onnx model file)")
    suffix = path.suffix.lower()
    if suffix not in (*KERAS_SUFFIXES, ONNX_SUFFIX):
        raise ModelFileError(f"{path}: expected a .keras, .h5 or .onnx model file")
    size = path.stat().st_size
    if size > MAX_MODEL_BYTES:
        raise ModelFileError(
            f"{path}: {size / 2**30:.1f} GiB is over the {MAX_MODEL_BYTES >> 30} GiB limit for "
            "a model file"
        )
    if size == 0:
        raise ModelFileError(f"{path}: empty file, not a model file")
    if suffix == ONNX_SUFFIX:
        if runtime == "keras":
            raise ModelFileError(f"{path}: an ONNX model runs with --runtime onnx, not keras")
        from clonedrive.network.onnx_runtime import OnnxModel

        return OnnxModel.from_file(path)
    model = _read_keras(path, trust=trust)
    if runtime == "onnx":
        from clonedrive.network.onnx_runtime import OnnxModel, onnx_bytes

        return OnnxModel(onnx_bytes(model), source=f"{path} (converted to ONNX)")
    return model


# --------------------------------------------------------------------------- Keras files


def _read_keras(path: Path, *, trust: bool) -> Any:
    kind, config, lambdas, legacy = _checked_keras(path, trust=trust)
    if lambdas:
        logger.warning(TRUST_WARNING.format(path=path, names=", ".join(lambdas)))
    if legacy:
        from clonedrive.network import legacy_keras

        return legacy_keras.load(path, config, lambdas=lambdas)
    return keras_load(path, safe_mode=not lambdas)


def check_keras_file(path: str | Path) -> None:
    """Everything :func:`read_model` checks in a ``.keras`` or ``.h5`` file before loading it
    (its kind, its configuration, no Lambda layers, the memory it would take), for the code
    that loads a file with Keras itself (a resumed training run, the report's network table).
    Raises :class:`ModelFileError`."""
    _checked_keras(Path(path), trust=False)


def _checked_keras(path: Path, *, trust: bool) -> tuple[str, dict, list[str], bool]:
    """(the file's kind, its configuration, its Lambda layers, whether Keras 1/2 saved it),
    after every check that needs no model built."""
    kind = file_kind(path)
    suffix = path.suffix.lower()
    if kind == "other":
        expected = "a zip archive" if suffix == ".keras" else "an HDF5 file"
        raise ModelFileError(
            f"{path}: not a Keras model file (a {suffix} model is {expected}; this file starts "
            f"with {_head_text(path)})"
        )
    if kind == "zip" and suffix != ".keras":
        raise ModelFileError(f"{path}: a Keras 3 .keras archive named {suffix}: rename it .keras")
    if kind == "hdf5" and suffix == ".keras":
        raise ModelFileError(f"{path}: an HDF5 model file named .keras: rename it .h5")

    config, keras_version = model_config(path, kind)
    lambdas = lambda_layer_names(config)
    if lambdas and not trust:
        raise ModelFileError(
            f"{path}: has Lambda layers ({', '.join(lambdas)}): Python code stored in the file, "
            "which Keras safe mode refuses to run. If you trust where the file came from, add "
            "--trust-model"
        )
    from clonedrive.network import legacy_keras

    legacy = kind == "hdf5" and legacy_keras.is_legacy_version(keras_version)
    _check_memory(path, kind, config, lambdas=lambdas, legacy=legacy)
    return kind, config, lambdas, legacy


#: What building a network from a configuration may raise for a file that is not a model
#: Keras can build (Keras's loader raises the same).
_BUILD_ERRORS = (ValueError, TypeError, OSError, KeyError, AttributeError, IndexError,
                 RecursionError, RuntimeError, NotImplementedError)


def _check_memory(path: Path, kind: str, config: dict, *, lambdas: list[str],
                  legacy: bool) -> None:
    """Refuse a file whose configuration declares more weights than it stores, or whose
    weights unpack past the limits, before Keras allocates anything
    (:mod:`clonedrive.network.model_bounds`)."""
    from clonedrive.network import model_bounds

    stored = _stored_weight_bytes(path, kind)
    model_bounds.check_declared_shapes(path, config)
    safe_mode = not lambdas
    if kind == "zip":
        builders = [model_bounds.keras_archive_network(config, safe_mode=safe_mode)]
    else:
        builders = [model_bounds.keras_h5_network(config, safe_mode=safe_mode)]
    if legacy:  # what legacy_keras.load falls back to, and the only way for stored code
        from clonedrive.network.legacy_keras import rebuilt_network

        rebuilt = [lambda: rebuilt_network(path, config)[0]]
        builders = rebuilt if lambdas else [*rebuilt, *builders]
    first_error: BaseException | None = None
    for build in builders:
        try:
            declared = model_bounds.declared_weight_bytes(build)
        except _BUILD_ERRORS as error:
            first_error = first_error or error
            continue
        model_bounds.check_declared(path, declared, stored)
        return
    raise ModelFileError(f"{path}: cannot load the model: {one_line(first_error)}")


def _stored_weight_bytes(path: Path, kind: str) -> int:
    """Bytes of the weights ``path`` stores (HDF5 dataset shapes; the members' unpacked sizes
    for an archive that stores them otherwise), checked against the limits."""
    from clonedrive.network.model_bounds import WEIGHTS_MEMBER, stored_weight_bytes

    if kind == "hdf5":
        return stored_weight_bytes(path, path, path.stat().st_size)
    with zipfile.ZipFile(path) as archive:
        if WEIGHTS_MEMBER not in archive.namelist():
            return sum(info.file_size for info in archive.infolist()
                       if info.filename not in ("config.json", "metadata.json"))
        info = archive.getinfo(WEIGHTS_MEMBER)
        with archive.open(info) as member:
            return stored_weight_bytes(path, member, info.file_size)


def _head_text(path: Path) -> str:
    with open(path, "rb") as handle:
        head = handle.read(8)
    return "0x" + head.hex() if head else "nothing"

