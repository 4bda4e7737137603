"""A Keras model's forward pass traced by PyTorch: the same operations without Keras's Python.

On the PyTorch backend Keras 3 runs every layer call through Python bookkeeping (names, dtype
policies, masks, the functional graph). For our small networks that costs more than the
arithmetic, which a trace leaves out.

:class:`TracedForward` traces the model (``torch.jit.trace`` of the Keras model, itself a
``torch.nn.Module``) once per batch size, since a trace records its shapes. It trusts a trace only
once its outputs have equalled ``predict_on_batch``'s on that first batch bit for bit. A model
that cannot be traced, or whose trace differs, keeps running through ``predict_on_batch``, and
the first time that happens to a model one INFO line on the ``clonedrive.model`` logger says
why. So a policy steers the same to the last bit either way; only the time changes.
"""

from __future__ import annotations

import io
import logging
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from clonedrive.network.crop import visible_rows

#: Batch sizes traced per model at most (a policy predicts one size, a frame or a frame and its
#: mirror image; other callers may pass others); beyond it, predict_on_batch.
MAX_TRACES = 16

logger = logging.getLogger("clonedrive.model")


class TracedForward:
    """``predict_on_batch`` for a Keras model on the PyTorch backend, run by a trace when a
    trace of that batch size has been checked against it (see the module doc)."""

    def __init__(self, model: Any) -> None:
        self.model = model
        self._traces: dict[tuple, Any] = {}  # input shape -> checked trace, or None: not used
        self._untraced_reported = False  # the reason a shape runs untraced was logged

    def __call__(self, images: np.ndarray) -> np.ndarray | list[np.ndarray]:
        import torch

        key = images.shape
        trace = self._traces.get(key)
        if trace is not None:
            with torch.inference_mode():
                return _numpy(trace(_tensor(images)))
        expected = self.model.predict_on_batch(images)
        if key not in self._traces and len(self._traces) < MAX_TRACES:
            self._traces[key] = self._checked_trace(images, expected)
        return expected

    @property
    def traced_shapes(self) -> list[tuple]:
        """The input shapes that run traced (tests, diagnostics)."""
        return [shape for shape, trace in self._traces.items() if trace is not None]

    def _checked_trace(self, images: np.ndarray, expected) -> Any:
        import torch

        batch = _tensor(images)
        try:
            with warnings.catch_warnings(), torch.no_grad():
                # Keras's shape checks are Python conditions: the trace warns that it records
                # their outcome for these shapes, which is what it is used for.
                warnings.simplefilter("ignore")
                trace = torch.jit.trace(self.model, (batch,), check_trace=False)
            with torch.inference_mode():
                got = _numpy(trace(batch))
        # What torch raises for a model it cannot trace: RuntimeError from the tracer (a dict
        # or other non-tensor output...), ValueError for the module's structure (backward
        # hooks, parameters shared between modules), torch.jit.Error from running the trace.
        except (RuntimeError, ValueError, torch.jit.Error) as error:
            self._report_untraced(images.shape, f"torch cannot trace it ({type(error).__name__}: "
                                  f"{_first_line(error)})")
            return None
        if not _same(got, expected):
            self._report_untraced(images.shape, "its trace's outputs differ from "
                                  "predict_on_batch's")
            return None
        return trace

    def _report_untraced(self, shape: tuple, reason: str) -> None:
        """Log, once per model, why a batch shape keeps ``predict_on_batch``."""
        level = logging.DEBUG if self._untraced_reported else logging.INFO
        self._untraced_reported = True
        logger.log(level, "model %s runs through predict_on_batch for batches of shape %s: %s",
                   getattr(self.model, "name", "?"), tuple(shape), reason)

    def portable(self, batch_sizes: Sequence[int], *, seed: int = 0) -> PortableModel | None:
        """The model as its checked traces, one per batch size, for a worker process to run
        without importing Keras (:class:`TracedModel`; ``import keras`` costs a fresh process
        about 5.4 s on the development machine, ``import torch`` alone 2.2 s). Each trace is
        checked against ``predict_on_batch`` on a batch of random frames first, as in
        :meth:`__call__`; a size that :meth:`__call__` already found not to trace exactly is
        not tried again. None if any size cannot be traced exactly: the worker then loads the
        model file as before (and so drives as this process does)."""
        import torch

        images = np.random.default_rng(seed).integers(
            0, 256, (max(batch_sizes), *self.model.inputs[0].shape[1:]), dtype=np.uint8)
        images = images.astype(tensor_dtype(self.model.inputs[0]), copy=False)
        traces = {}
        for size in sorted(set(int(size) for size in batch_sizes)):
            batch = images[:size]
            if batch.shape in self._traces:
                trace = self._traces[batch.shape]
            else:
                trace = self._checked_trace(batch, self.model.predict_on_batch(batch))
                if len(self._traces) < MAX_TRACES:
                    self._traces[batch.shape] = trace
            if trace is None:  # this process predicts that size without the trace
                return None
            buffer = io.BytesIO()
            torch.jit.save(trace, buffer)
            traces[size] = buffer.getvalue()
        return PortableModel(
            traces=traces,
            inputs=tuple(_spec(item) for item in self.model.inputs),
            outputs=tuple(_spec(item) for item in self.model.outputs),
            output_names=tuple(getattr(self.model, "output_names", None) or ()),
            name=str(getattr(self.model, "name", "model")),
            visible_rows=visible_rows(self.model))


@dataclass(frozen=True)
class PortableModel:
    """A model's checked traces (TorchScript bytes per batch size) and its input and output
    specs: what :class:`TracedModel` needs, picklable for a worker process."""

    traces: dict[int, bytes]
    inputs: tuple
    outputs: tuple
    output_names: tuple[str, ...]
    name: str
    visible_rows: tuple[int, int] | None = None  #: the model's crop (network.crop)


class TracedModel:
    """Runs a :class:`PortableModel` like a Keras model's ``predict_on_batch``, with PyTorch
    alone: the same traces, so the same outputs to the last bit as the model they came from.
    A batch size it has no trace for is refused (the caller asked for every size it uses)."""

    def __init__(self, portable: PortableModel) -> None:
        import torch

        self._traces = {size: torch.jit.load(io.BytesIO(data))
                        for size, data in portable.traces.items()}
        self.inputs = list(portable.inputs)
        self.outputs = list(portable.outputs)
        self.output_names = list(portable.output_names)
        self.name = portable.name
        self.visible_rows = portable.visible_rows

    def predict_on_batch(self, images: np.ndarray) -> np.ndarray | list[np.ndarray]:
        import torch

        trace = self._traces.get(len(images))
        if trace is None:
            raise ValueError(f"{self.name}: no trace for a batch of {len(images)} frames "
                             f"(traced: {sorted(self._traces)})")
        with torch.inference_mode():
            return _numpy(trace(_tensor(np.asarray(images))))

    def __repr__(self) -> str:
        return f"TracedModel({self.name!r}, batch sizes {sorted(self._traces)})"


def _spec(tensor: Any):
    from clonedrive.network.onnx_runtime import TensorSpec

    shape = tuple(dim if isinstance(dim, int) else None for dim in tensor.shape)
    return TensorSpec(str(getattr(tensor, "name", "")), shape, tensor_dtype(tensor))


def tensor_dtype(tensor: Any) -> np.dtype:
    """The NumPy dtype of a model's input or output (float32 unless it says otherwise)."""
    dtype = getattr(tensor, "dtype", None)
    try:
        return np.dtype(dtype) if dtype is not None else np.dtype(np.float32)
    except TypeError:  # a backend dtype numpy does not know
        return np.dtype(np.float32)


def _tensor(images: np.ndarray):
    import torch

    # torch.from_numpy wants its own writable, contiguous array with no negative stride (one
    # frame of a reversed batch counts as contiguous in numpy but keeps its negative stride).
    if not (images.flags.writeable and images.flags.c_contiguous) or min(images.strides) < 0:
        images = np.array(images)
    return torch.from_numpy(images)


def _numpy(output) -> np.ndarray | list[np.ndarray]:
    if isinstance(output, list | tuple):
        return [item.detach().cpu().numpy() for item in output]
    return output.detach().cpu().numpy()


def _first_line(error: BaseException) -> str:
    """An exception's message up to its first line break (torch's run to many lines)."""
    text = str(error).strip()
    return text.splitlines()[0][:200] if text else "no message"


def _same(a, b) -> bool:
    a = a if isinstance(a, list) else [a]
    b = list(b) if isinstance(b, list | tuple) else [b]
    # array_equal is False for different shapes too.
    return len(a) == len(b) and all(np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
                                    for x, y in zip(a, b, strict=True))


def forward_for(model: Any) -> Callable[[np.ndarray], Any]:
    """What runs ``model`` on a batch: a :class:`TracedForward` for a Keras model on the
    PyTorch backend, else the model's own ``predict_on_batch`` (ONNX Runtime, other backends)."""
    import sys

    torch = sys.modules.get("torch")
    if torch is not None and isinstance(model, torch.nn.Module) \
            and hasattr(model, "predict_on_batch"):
        return TracedForward(model)
    return model.predict_on_batch
