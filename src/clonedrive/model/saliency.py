"""VisualBackProp (Bojarski et al. 2016, "VisualBackProp: efficient visualization of CNNs"):
which pixels of the camera frame the convolutional layers respond to.

For each convolutional layer the feature maps (after ReLU) are averaged over channels. Starting
at the deepest layer, the averaged map is scaled up to the size of the layer below by a
transposed convolution with the layer's kernel size and stride and all-ones weights, and
multiplied point by point with that layer's averaged map; the product goes down the same way,
until the input of the first convolution is reached. The result is a mask of the input's size
that is high where the network's features are active at every depth: for a driving network,
the road's edges and lines. It needs one forward pass and no gradients.

The first convolution here sees a cropped (and, for ``fast`` and ``pilotnet``, downsampled)
frame; the mask is resized to the crop and placed into a full 160x320 mask (zero in the rows
the model crops away). Masks are normalised to [0, 1] per frame.

Which layers count: every trainable ``Conv2D`` with a kernel larger than 1x1, in order (the
frozen 1x1 RGB->YUV layer of ``pilotnet`` is a colour conversion, not a feature detector).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clonedrive.base.keras_backend import import_keras
from clonedrive.base.udacity_spec import IMAGE_HEIGHT, IMAGE_SHAPE, IMAGE_WIDTH

#: Colour [R, G, B] the mask is painted in on overlays (the paper shows it in green).
OVERLAY_RGB = (40, 255, 60)
#: Frames taken from each driving log given to :func:`write_saliency`, evenly spaced.
DEFAULT_FRAMES_PER_LOG = 12
#: Frames :func:`write_saliency` handles at most in one call (time and disk stay bounded).
MAX_FRAMES = 2000


@dataclass(frozen=True)
class _ConvStage:
    name: str
    kernel: tuple[int, int]
    strides: tuple[int, int]
    channels_first: bool


class VisualBackProp:
    """Saliency masks of ``model`` (a clonedrive steering model, one frame input)."""

    def __init__(self, model) -> None:
        keras = import_keras()
        convs = [layer for layer in model.layers
                 if isinstance(layer, keras.layers.Conv2D) and layer.trainable
                 and tuple(layer.kernel_size) != (1, 1)]
        if not convs:
            raise ValueError(f"model {model.name!r} has no convolutional layer: VisualBackProp "
                             "needs a convolutional network")
        self.stages = [
            _ConvStage(layer.name, tuple(layer.kernel_size), tuple(layer.strides),
                       layer.data_format == "channels_first")
            for layer in convs
        ]
        first_input = convs[0].input
        shape = tuple(first_input.shape)[1:]
        self._first_input_hw = shape[1:3] if self.stages[0].channels_first else shape[0:2]
        self._rows = _kept_rows(model, keras)
        # One forward pass gives every conv layer's feature maps (and the predictions).
        inputs = model.inputs[0] if len(model.inputs) == 1 else model.inputs
        self._features = keras.Model(inputs, [layer.output for layer in convs],
                                     name=f"{model.name}_features")

    def masks(self, images: np.ndarray) -> np.ndarray:
        """``(N, 160, 320)`` float32 masks in [0, 1] for uint8 RGB frames ``(N, 160, 320, 3)``."""
        images = np.asarray(images)
        if images.ndim == 3:
            images = images[np.newaxis]
        if images.shape[1:] != (IMAGE_HEIGHT, IMAGE_WIDTH, 3):
            raise ValueError(f"expected frames of shape (N, {IMAGE_HEIGHT}, {IMAGE_WIDTH}, 3), "
                             f"got {images.shape}")
        outputs = self._features.predict_on_batch(images.astype(np.float32))
        if not isinstance(outputs, list | tuple):
            outputs = [outputs]
        averaged = [_channel_mean(np.asarray(maps), stage.channels_first)
                    for maps, stage in zip(outputs, self.stages, strict=True)]
        mask = averaged[-1]
        for depth in range(len(self.stages) - 1, 0, -1):
            stage = self.stages[depth]
            below = averaged[depth - 1]
            mask = _fit(_spread(mask, stage.kernel, stage.strides), below.shape[1:]) * below
        mask = _fit(_spread(mask, self.stages[0].kernel, self.stages[0].strides),
                    self._first_input_hw)
        return self._to_frame(mask)

    def _to_frame(self, masks: np.ndarray) -> np.ndarray:
        import cv2

        top, bottom = self._rows
        frame = np.zeros((len(masks), IMAGE_HEIGHT, IMAGE_WIDTH), dtype=np.float32)
        for index, mask in enumerate(masks):
            resized = cv2.resize(mask.astype(np.float32), (IMAGE_WIDTH, bottom - top),
                                 interpolation=cv2.INTER_LINEAR)
            peak = float(resized.max())
            frame[index, top:bottom] = resized / peak if peak > 0 else 0.0
        return np.clip(frame, 0.0, 1.0)


def _kept_rows(model, keras) -> tuple[int, int]:
    """The frame rows [top, bottom) the model's first Cropping2D keeps (all without one)."""
    for layer in model.layers:
        if isinstance(layer, keras.layers.Cropping2D):
            (top, bottom), _ = layer.cropping
            return int(top), IMAGE_HEIGHT - int(bottom)
    return 0, IMAGE_HEIGHT


def _channel_mean(maps: np.ndarray, channels_first: bool) -> np.ndarray:
    """(N, H, W) channel average of feature maps, each frame's map scaled to [0, 1]."""
    mean = maps.mean(axis=1 if channels_first else 3).astype(np.float32)
    peak = mean.reshape(len(mean), -1).max(axis=1)
    return mean / np.where(peak > 0, peak, 1.0)[:, None, None]


def _spread(mask: np.ndarray, kernel: tuple[int, int], strides: tuple[int, int]) -> np.ndarray:
    """Transposed convolution of (N, H, W) maps with an all-ones ``kernel`` at ``strides``:
    each value is added to the kernel-sized patch of the layer's input it was computed from."""
    count, height, width = mask.shape
    (kh, kw), (sh, sw) = kernel, strides
    out = np.zeros((count, (height - 1) * sh + kh, (width - 1) * sw + kw), dtype=np.float32)
    for row in range(kh):
        for column in range(kw):
            out[:, row:row + (height - 1) * sh + 1:sh, column:column + (width - 1) * sw + 1:sw] \
                += mask
    return out


def _fit(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(N, H, W) maps cut or zero-padded at the bottom/right to ``size`` (a "valid"
    convolution drops the last rows/columns its stride cannot reach); resized if the sizes
    are further apart (a pooling layer between convolutions)."""
    import cv2

    height, width = size
    if abs(mask.shape[1] - height) > 8 or abs(mask.shape[2] - width) > 8:
        return np.stack([cv2.resize(item, (width, height), interpolation=cv2.INTER_LINEAR)
                         for item in mask])
    out = np.zeros((len(mask), height, width), dtype=np.float32)
    rows, columns = min(height, mask.shape[1]), min(width, mask.shape[2])
    out[:, :rows, :columns] = mask[:, :rows, :columns]
    return out


def overlay(image_rgb: np.ndarray, mask: np.ndarray, *, strength: float = 0.8) -> np.ndarray:
    """The frame, slightly darkened, with ``mask`` painted in :data:`OVERLAY_RGB` on top."""
    image = image_rgb.astype(np.float32)
    weight = np.clip(mask, 0.0, 1.0)[..., None] * strength
    colour = np.array(OVERLAY_RGB, dtype=np.float32)
    blended = image * 0.7 * (1.0 - weight) + colour * weight
    return np.clip(blended, 0, 255).astype(np.uint8)


def write_saliency(model_path: str | os.PathLike, sources: list[str | os.PathLike],
                   out_dir: str | os.PathLike, *, frames_per_log: int = DEFAULT_FRAMES_PER_LOG
                   ) -> dict:
    """Overlays of the VisualBackProp mask for image files and driving logs (a folder holding
    ``driving_log.csv``, or the CSV: ``frames_per_log`` center frames, evenly spaced).

    Writes ``<name>_saliency.png`` per frame (names made safe, unique) and ``saliency.json``
    (per frame: source, overlay, predicted steering and, with a speed head, target speed)
    into ``out_dir``; returns what ``saliency.json`` holds. ``ValueError`` for an input that
    is neither a readable image nor a log.
    """
    from clonedrive.base.config import write_json_atomic
    from clonedrive.base.paths import check_output_folder, inside, safe_stem
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.network.model_file import load_model

    if frames_per_log < 1:
        raise ValueError(f"frames per log must be >= 1, got {frames_per_log}")
    out = check_output_folder(out_dir)
    frames = _gather_frames(sources, frames_per_log)
    model = load_model(model_path)
    policy = NetworkPolicy(model)
    saliency = VisualBackProp(model)
    out.mkdir(parents=True, exist_ok=True)
    entries, taken = [], set()
    for start in range(0, len(frames), 32):
        chunk = frames[start:start + 32]
        images = np.stack([image for _, image in chunk])
        masks = saliency.masks(images)
        steering, speed = policy.predict(images)
        for index, ((source, image), mask) in enumerate(zip(chunk, masks, strict=True)):
            stem = safe_stem(Path(source).stem)
            name, number = f"{stem}_saliency.png", 1
            while name in taken:
                number += 1
                name = f"{stem}-{number}_saliency.png"
            taken.add(name)
            write_png(inside(out, name), overlay(image, mask))
            entry = {"source": str(source), "overlay": name,
                     "steering": round(float(steering[index]), 4)}
            if speed is not None:
                entry["target_speed_mph"] = round(float(speed[index]), 2)
            entries.append(entry)
    report = {"model": str(model_path), "method": "VisualBackProp (Bojarski et al. 2016)",
              "layers": [stage.name for stage in saliency.stages], "frames": entries}
    write_json_atomic(out / "saliency.json", report)
    return report


def _gather_frames(sources, frames_per_log: int) -> list[tuple[str, np.ndarray]]:
    from clonedrive.base.images import ImageDecodeError, read_rgb
    from clonedrive.data.driving_log import CSV_NAME, read_driving_log

    if not sources:
        raise ValueError("give at least one image or driving log")
    frames: list[tuple[str, np.ndarray]] = []
    for source in sources:
        path = Path(source)
        if path.is_dir() or path.name == CSV_NAME:
            if not (path / CSV_NAME).is_file() and not path.is_file():
                raise ValueError(f"{path}: a folder without {CSV_NAME}; give images or logs")
            rows = read_driving_log(path).rows
            if not rows:
                raise ValueError(f"{path}: the driving log has no usable row")
            picks = np.unique(np.linspace(0, len(rows) - 1, min(frames_per_log, len(rows)))
                              .round().astype(int))
            paths = [rows[int(index)].center for index in picks]
        else:
            paths = [path]
        for image_path in paths:
            try:
                frames.append((str(image_path), read_rgb(image_path, shape=IMAGE_SHAPE)))
            except ImageDecodeError as error:
                raise ValueError(str(error)) from None
            if len(frames) > MAX_FRAMES:
                raise ValueError(f"more than {MAX_FRAMES} frames; give fewer images or logs")
    return frames


def write_png(path: str | os.PathLike, image_rgb: np.ndarray) -> Path:
    """Write a uint8 RGB image as a PNG, atomically."""
    import cv2

    from clonedrive.base.config import write_bytes_atomic

    ok, data = cv2.imencode(".png", np.ascontiguousarray(image_rgb[:, :, ::-1]))
    if not ok:
        raise ValueError(f"{path}: OpenCV could not encode the image")
    return write_bytes_atomic(path, data.tobytes())
