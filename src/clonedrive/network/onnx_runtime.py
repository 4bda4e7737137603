"""Steering models as ONNX: export from Keras, run with ONNX Runtime.

:func:`export_onnx` writes a Keras model as an ``.onnx`` file through Keras 3's own exporter
(``model.export(path, format="onnx")``; on the torch backend that is PyTorch's TorchScript ONNX
exporter, with a dynamic batch dimension) and names the graph's outputs as the Keras model's
(``steering``, and ``target_speed`` for a speed head) so that a runtime finds them by name. The
input keeps its Keras name and dtype (``image_rgb``, uint8 for clonedrive's models).

:class:`OnnxModel` wraps an ``onnxruntime.InferenceSession`` with the part of the Keras model
interface the policy uses (``inputs``, ``outputs``, ``output_names``, ``predict_on_batch``), so
:class:`~clonedrive.drivers.policy.NetworkPolicy` drives with it unchanged.

Needs the ``onnx`` extra (``pip install -e ".[onnx]"``): ``onnx`` and ``onnxruntime``.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from clonedrive.base.config import write_bytes_atomic

#: The ONNX tensor element types a steering model's input may have, as NumPy dtypes.
_ONNX_DTYPES = {"tensor(uint8)": np.uint8, "tensor(float)": np.float32,
                "tensor(double)": np.float64}
EXTRA_HINT = 'ONNX needs the onnx extra: pip install -e ".[onnx]" (onnx and onnxruntime)'


@dataclass(frozen=True)
class TensorSpec:
    """Name, shape (None for a dynamic dimension) and dtype of a model input or output."""

    name: str
    shape: tuple[int | None, ...]
    dtype: Any


def _import(module: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ModuleNotFoundError:
        raise ValueError(f"{EXTRA_HINT} ({module} is not installed)") from None


class OnnxModel:
    """An ONNX steering model run by ONNX Runtime on the CPU.

    ``model``: the ``.onnx`` bytes (or use :meth:`from_file`). ``threads``: ONNX Runtime's
    intra-op threads (None: its default, one per physical core).
    """

    def __init__(self, model: bytes, *, source: str = "<onnx>", threads: int | None = None):
        ort = _import("onnxruntime")
        options = ort.SessionOptions()
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        if threads is not None:
            options.intra_op_num_threads = int(threads)
        # Idle threads sleep instead of spinning: the server predicts one frame at 15 Hz, on a
        # machine that may also run the simulator.
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        try:
            self.session = ort.InferenceSession(model, options, providers=["CPUExecutionProvider"])
        except Exception as error:  # onnxruntime raises its own untyped errors for bad files
            text = " ".join(str(error).split())[:300]
            raise ValueError(f"{source}: not an ONNX model ONNX Runtime can run ({text})") from None
        self.source = source
        self.inputs = [_spec(item) for item in self.session.get_inputs()]
        self.outputs = [_spec(item) for item in self.session.get_outputs()]
        self.output_names = [spec.name for spec in self.outputs]
        self.name = Path(source).stem

    @classmethod
    def from_file(cls, path: str | os.PathLike, *, threads: int | None = None) -> OnnxModel:
        return cls(Path(path).read_bytes(), source=str(path), threads=threads)

    def predict_on_batch(self, images: np.ndarray) -> np.ndarray | list[np.ndarray]:
        """The outputs for a batch, as Keras's ``predict_on_batch`` returns them: one array for
        a one-output model, else a list in output order."""
        spec = self.inputs[0]
        batch = np.asarray(images)
        if spec.dtype == np.uint8 and batch.dtype != np.uint8:
            batch = np.clip(np.rint(batch), 0, 255)  # whole numbers 0..255: exact
        batch = np.ascontiguousarray(batch, dtype=spec.dtype)
        outputs = self.session.run(None, {spec.name: batch})
        return outputs[0] if len(outputs) == 1 else list(outputs)

    def __repr__(self) -> str:
        return f"OnnxModel({self.source!r})"


def _spec(node: Any) -> TensorSpec:
    shape = tuple(dim if isinstance(dim, int) else None for dim in node.shape)
    return TensorSpec(node.name, shape, _ONNX_DTYPES.get(node.type, np.float32))


def onnx_bytes(model: Any) -> bytes:
    """``model`` (Keras) as ONNX bytes: see :func:`export_onnx`."""
    with tempfile.TemporaryDirectory(prefix="clonedrive-onnx-") as folder:
        path = Path(folder) / "model.onnx"
        _export(model, path)
        return path.read_bytes()


def export_onnx(model: Any, path: str | os.PathLike) -> Path:
    """Write the Keras ``model`` to ``path`` as ONNX (atomically); returns the path."""
    path = Path(path)
    write_bytes_atomic(path, onnx_bytes(model))
    return path


def _export(model: Any, path: Path) -> None:
    onnx = _import("onnx")
    _import("onnxruntime")
    shape = tuple(model.inputs[0].shape)
    sample = np.zeros((1, *(dim or 1 for dim in shape[1:])), dtype=np.float32)
    model.predict_on_batch(sample)  # Keras exports only a model that has been called
    import torch  # the torch backend's exporter warns about every traced shape: not news

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        warnings.filterwarnings("ignore", category=UserWarning)
        model.export(str(path), format="onnx", verbose=False)
    graph_model = onnx.load(str(path))
    _name_outputs(graph_model.graph, [str(name) for name in model.output_names])
    onnx.checker.check_model(graph_model)
    onnx.save(graph_model, str(path))


def _name_outputs(graph: Any, names: list[str]) -> None:
    """Rename the graph's outputs to the Keras output names (the exporter numbers them)."""
    if len(names) != len(graph.output):
        return
    renames = {output.name: name for output, name in zip(graph.output, names, strict=True)
               if output.name != name}
    taken = {value for node in graph.node for value in (*node.input, *node.output)}
    if any(name in taken for name in renames.values()):
        return  # a name already used inside the graph: keep the exporter's names
    for output in graph.output:
        output.name = renames.get(output.name, output.name)
    for node in graph.node:
        for index, value in enumerate(node.output):
            if value in renames:
                node.output[index] = renames[value]
        for index, value in enumerate(node.input):
            if value in renames:
                node.input[index] = renames[value]
