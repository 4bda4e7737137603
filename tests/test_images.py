"""The one image decoder: RGB out, one error type whose message names the file."""

import cv2
import numpy as np
import pytest

from clonedrive.base.images import ImageDecodeError, decode_rgb, read_rgb


def red_left_blue_right(height: int = 16, width: int = 32) -> np.ndarray:
    image = np.zeros((height, width, 3), np.uint8)
    image[:, : width // 2] = (255, 0, 0)
    image[:, width // 2 :] = (0, 0, 255)
    return image


def png_bytes(image_rgb: np.ndarray) -> bytes:
    ok, buffer = cv2.imencode(".png", image_rgb[..., ::-1])  # OpenCV writes BGR
    assert ok
    return buffer.tobytes()


def test_decodes_to_rgb_from_bytes_and_from_a_file(tmp_path):
    image = red_left_blue_right()
    np.testing.assert_array_equal(decode_rgb(png_bytes(image)), image)
    path = tmp_path / "frame.png"
    path.write_bytes(png_bytes(image))
    np.testing.assert_array_equal(read_rgb(path, shape=(16, 32, 3)), image)
    into = np.zeros_like(image)
    assert read_rgb(path, into) is into
    np.testing.assert_array_equal(into, image)


@pytest.mark.parametrize("data", [b"", b"not an image", b"\xff\xd8\xff\xe0" + b"\x00" * 20])
def test_bytes_that_do_not_decode_name_the_image(data):
    with pytest.raises(ImageDecodeError, match=r"^frame\.jpg does not decode") as error:
        decode_rgb(data, name="frame.jpg")
    assert error.value.reason == "image_corrupt"


def test_wrong_size_and_missing_files_name_the_file(tmp_path):
    path = tmp_path / "small.png"
    path.write_bytes(png_bytes(red_left_blue_right()))
    with pytest.raises(ImageDecodeError, match=r"small\.png is 32x16, expected 320x160") as error:
        read_rgb(path, shape=(160, 320, 3))
    assert error.value.reason == "image_size"
    with pytest.raises(ImageDecodeError, match=r"gone\.jpg cannot be read") as error:
        read_rgb(tmp_path / "gone.jpg")
    assert error.value.reason == "image_missing"
