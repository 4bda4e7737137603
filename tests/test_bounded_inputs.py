"""Inputs that would fill the memory are refused before anything is allocated: an image whose
header declares a huge picture (checked in the one decoder, so every reader gets it), and
counts on the command line beyond a stated maximum."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from clonedrive.base.images import (
    IMAGE_CORRUPT,
    IMAGE_SIZE,
    MAX_IMAGE_PIXELS,
    ImageDecodeError,
    check_image_header,
    decode_rgb,
    read_rgb,
)
from clonedrive.cli import main


def png_header(width: int, height: int) -> bytes:
    """A PNG's signature and IHDR chunk (8-bit RGB) declaring ``width`` x ``height``, and a
    short IDAT: enough for any decoder to start allocating."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    chunk = (struct.pack(">I", len(ihdr)) + b"IHDR" + ihdr
             + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr)))
    idat = zlib.compress(b"\0" * 4096)
    return (b"\x89PNG\r\n\x1a\n" + chunk + struct.pack(">I", len(idat)) + b"IDAT" + idat
            + struct.pack(">I", zlib.crc32(b"IDAT" + idat)))


def test_a_huge_png_named_center_jpg_is_refused_from_its_header(tmp_path: Path) -> None:
    path = tmp_path / "center.jpg"
    path.write_bytes(png_header(30000, 30000))
    with pytest.raises(ImageDecodeError) as refused:
        read_rgb(path)
    assert refused.value.reason == IMAGE_SIZE
    assert str(refused.value) == (f"{path} declares 30000x30000 pixels; the limit is "
                                  f"{MAX_IMAGE_PIXELS} pixels (4096x4096): not decoded")


def test_sizes_come_from_the_header_of_real_files() -> None:
    import cv2

    image = np.zeros((37, 91, 3), dtype=np.uint8)
    for suffix in (".jpg", ".png"):
        encoded = cv2.imencode(suffix, image)[1]
        assert check_image_header(encoded) == (91, 37)
        assert check_image_header(encoded.tobytes()) == (91, 37)
        assert decode_rgb(encoded.tobytes()).shape == (37, 91, 3)


@pytest.mark.parametrize("data", [b"", b"GIF89a....", b"\x89PNG\r\n\x1a\n", b"\xff\xd8\xff"])
def test_what_is_no_jpeg_or_png_does_not_decode(data: bytes) -> None:
    with pytest.raises(ImageDecodeError, match="does not decode as an image") as refused:
        decode_rgb(data, name="x")
    assert refused.value.reason == IMAGE_CORRUPT


@pytest.mark.parametrize("option", [["--unseen", "1000000000"], ["--laps", "1000000"],
                                    ["--batch", "100000"]])
def test_evaluate_counts_have_a_stated_maximum(option: list[str], tmp_path: Path,
                                               capsys) -> None:
    status = main(["evaluate", str(tmp_path / "model.keras"), *option])
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith("clonedrive evaluate: ") and "must be at most" in err
    assert err.count("\n") == 1
