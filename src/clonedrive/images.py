"""Decoding image files and bytes: the one place that calls OpenCV's decoder.

Every reader of a JPEG or PNG -- the dataset cache, ``check``'s decode verification, the drive
server's telemetry, ``video``'s frames, the report's pictures -- goes through
:func:`decode_rgb` or :func:`read_rgb`, so all of them get **RGB** (OpenCV decodes to BGR:
the classic bug of Udacity's starter kit) and the same errors, each naming the file. A
bottom-layer module: OpenCV is imported only when an image is decoded.
"""

from __future__ import annotations

import os

import numpy as np

#: Reasons an image cannot be used (``ImageDecodeError.reason``).
IMAGE_MISSING, IMAGE_CORRUPT, IMAGE_SIZE = "image_missing", "image_corrupt", "image_size"


class ImageDecodeError(ValueError):
    """An image that cannot be used; the message names it. ``reason`` is ``image_missing``
    (the file cannot be read), ``image_corrupt`` (does not decode) or ``image_size`` (not the
    expected shape)."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason


def decode_rgb(
    data: bytes | np.ndarray,
    out: np.ndarray | None = None,
    *,
    name: str = "image",
    shape: tuple[int, int, int] | None = None,
) -> np.ndarray:
    """Decode JPEG/PNG bytes to a uint8 RGB ``(height, width, 3)`` array.

    ``name`` (a file name, or what the bytes are) starts every error message. ``shape``:
    the (height, width, 3) the image must have (``image_size`` otherwise); None accepts any
    size. ``out``: a uint8 array of the image's shape to decode into (no new array).
    """
    import cv2

    buffer = np.frombuffer(data, dtype=np.uint8) if isinstance(data, bytes) else data
    bgr = None
    if buffer.size:
        try:
            bgr = cv2.imdecode(buffer, cv2.IMREAD_COLOR)
        except cv2.error:
            bgr = None
    if bgr is None:
        raise ImageDecodeError(IMAGE_CORRUPT, f"{name} does not decode as an image")
    if shape is not None and bgr.shape != tuple(shape):
        raise ImageDecodeError(
            IMAGE_SIZE,
            f"{name} is {bgr.shape[1]}x{bgr.shape[0]}, expected {shape[1]}x{shape[0]}",
        )
    if out is None:
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB, dst=out)
    return out


def read_rgb(
    path: str | os.PathLike,
    out: np.ndarray | None = None,
    *,
    shape: tuple[int, int, int] | None = None,
) -> np.ndarray:
    """Read an image file as uint8 RGB (see :func:`decode_rgb`); :class:`ImageDecodeError`
    naming ``path`` if it cannot be read, does not decode or has the wrong ``shape``."""
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as error:
        raise ImageDecodeError(
            IMAGE_MISSING, f"{path} cannot be read: {error.strerror or error}"
        ) from None
    return decode_rgb(data, out, name=str(path), shape=shape)
