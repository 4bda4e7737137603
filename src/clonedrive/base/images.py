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
#: Images with more pixels than this are refused from their header, before decoding: a small
#: file can declare a huge picture (30000x30000 is 2.7 GB decoded). 4096x4096: 50 MB as RGB.
MAX_IMAGE_PIXELS = 4096 * 4096
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


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
    check_image_header(buffer, name=name)
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


def check_image_header(data: bytes | np.ndarray, *, name: str = "image") -> tuple[int, int]:
    """``(width, height)`` from a JPEG's or PNG's header, before anything is decoded.

    :class:`ImageDecodeError` naming ``name``: ``image_corrupt`` for bytes that are neither
    (or whose header is cut short), ``image_size`` for more than :data:`MAX_IMAGE_PIXELS`
    pixels or a zero side.
    """
    view = memoryview(data if isinstance(data, bytes) else np.ascontiguousarray(data).reshape(-1))
    try:
        if bytes(view[:8]) == _PNG_SIGNATURE:
            size = _png_size(bytes(view[:24]))
        elif bytes(view[:2]) == b"\xff\xd8":
            size = jpeg_size(view)
        else:
            raise ValueError("not a JPEG or PNG")
    except ValueError as error:
        raise ImageDecodeError(IMAGE_CORRUPT,
                               f"{name} does not decode as an image ({error})") from None
    width, height = size
    if width * height > MAX_IMAGE_PIXELS or width == 0 or height == 0:
        raise ImageDecodeError(
            IMAGE_SIZE, f"{name} declares {width}x{height} pixels; the limit is "
                        f"{MAX_IMAGE_PIXELS} pixels (4096x4096): not decoded")
    return size


def _png_size(png: bytes) -> tuple[int, int]:
    """``(width, height)`` from a PNG's IHDR chunk (which must come first)."""
    if len(png) < 24 or png[12:16] != b"IHDR":
        raise ValueError("PNG without its IHDR header")
    return int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")


# JPEG start-of-frame markers carry the image size; C4 (DHT), C8 (JPG) and CC (DAC) do not.
_SOF_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
_STANDALONE_MARKERS = frozenset(range(0xD0, 0xD8)) | {0x01}


def jpeg_size(jpeg: bytes | memoryview) -> tuple[int, int]:
    """``(width, height)`` in pixels from a JPEG's header, without decoding it.

    Lets a server refuse a huge image before allocating it. Raises :class:`ValueError`.
    """
    if len(jpeg) < 4 or jpeg[:2] != b"\xff\xd8":
        raise ValueError("not a JPEG (no start-of-image marker)")
    position = 2
    while position + 4 <= len(jpeg):
        if jpeg[position] != 0xFF:
            raise ValueError(f"JPEG marker expected at byte {position}")
        marker = jpeg[position + 1]
        if marker == 0xFF:  # fill byte
            position += 1
            continue
        if marker in _STANDALONE_MARKERS:
            position += 2
            continue
        if marker in (0xD9, 0xDA):  # end of image / start of scan before any frame header
            break
        length = int.from_bytes(jpeg[position + 2 : position + 4], "big")
        if length < 2:
            raise ValueError(f"JPEG segment length {length} at byte {position}")
        if marker in _SOF_MARKERS:
            if position + 9 > len(jpeg):
                break
            height = int.from_bytes(jpeg[position + 5 : position + 7], "big")
            width = int.from_bytes(jpeg[position + 7 : position + 9], "big")
            return width, height
        position += 2 + length
    raise ValueError("JPEG has no frame header (truncated?)")
