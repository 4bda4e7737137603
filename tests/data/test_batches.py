"""Batches and the image cache: RGB end to end, one decode per image, the PyDataset contract."""

from __future__ import annotations

import base64
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from clonedrive.base.images import ImageDecodeError
from clonedrive.data.augment import AugmentConfig
from clonedrive.data.batches import DrivingBatches, ImageCache, read_rgb
from clonedrive.data.recipe import default_recipe_for, expand, parse_recipe

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"
LAKE = FIXTURES / "lake_posix_mixed_columns"


def _colour_frame() -> np.ndarray:
    """An RGB frame whose channels differ everywhere: red road edge, green grass, blue sky."""
    frame = np.zeros((160, 320, 3), dtype=np.uint8)
    frame[:60] = (60, 120, 230)  # sky: blue dominant
    frame[60:] = (40, 170, 50)  # grass: green dominant
    frame[100:, 100:220] = (200, 40, 30)  # red-brown road patch
    return frame


def _recording_with(tmp_path: Path, frame_rgb: np.ndarray) -> Path:
    """A one-row Udacity recording whose three images are ``frame_rgb`` written as JPEG the
    way the recorder writes frames (OpenCV, which expects BGR, after an RGB->BGR swap)."""
    folder = tmp_path / "rec"
    (folder / "IMG").mkdir(parents=True)
    names = [f"{camera}_2026_11_21_10_11_12_345.jpg" for camera in ("center", "left", "right")]
    for name in names:
        ok = cv2.imwrite(str(folder / "IMG" / name), cv2.cvtColor(frame_rgb, cv2.COLOR_RGB2BGR),
                         [cv2.IMWRITE_JPEG_QUALITY, 75])
        assert ok
    (folder / "driving_log.csv").write_text(
        ",".join(f"IMG/{name}" for name in names) + ",0.1,0.5,0,20\n", encoding="utf-8"
    )
    return folder


def test_training_and_driving_feed_the_network_identical_rgb_pixels(tmp_path: Path) -> None:
    """THE RGB TEST: the same frame, recorded to JPEG and read by the training pipeline, or sent
    as the drive server receives it (base64 JPEG, decoded with OpenCV, BGR -> RGB), gives the
    network the same pixels -- and they are RGB, not BGR."""
    frame = _colour_frame()
    folder = _recording_with(tmp_path, frame)

    # Training: recipe -> samples -> cache -> batch, no augmentation, center camera only.
    recipe = parse_recipe(f'[[recording]]\npath = "{folder.as_posix()}"\ncameras = "center"\n'
                          "flip = false\n")
    samples = expand(recipe)
    batches = DrivingBatches(samples, ImageCache(samples.unique_paths), batch_size=8)
    training_images, training_steering = batches[0]
    assert training_images.shape == (1, 160, 320, 3)
    assert training_steering.tolist() == [pytest.approx(0.1)]

    # Driving: the simulator sends the JPEG bytes base64-encoded in the telemetry event.
    jpeg = (folder / "IMG" / "center_2026_11_21_10_11_12_345.jpg").read_bytes()
    payload = base64.b64encode(jpeg).decode("ascii")
    received = cv2.imdecode(np.frombuffer(base64.b64decode(payload), np.uint8), cv2.IMREAD_COLOR)
    driving_image = cv2.cvtColor(received, cv2.COLOR_BGR2RGB)

    np.testing.assert_array_equal(training_images[0], driving_image)
    # And both are RGB: close to the original frame (JPEG loss only), far from its BGR twin.
    error_rgb = np.abs(driving_image.astype(int) - frame.astype(int)).mean()
    error_bgr = np.abs(driving_image.astype(int) - frame[..., ::-1].astype(int)).mean()
    assert error_rgb < 3 and error_bgr > 40
    sky, road = driving_image[20, 3], driving_image[130, 150]
    assert sky[2] > sky[0] and road[0] > road[2]  # blue sky, red road

    # The drive server's own decoder, where it exists, agrees too.
    protocol = pytest.importorskip("clonedrive.udacity.protocol")
    np.testing.assert_array_equal(protocol.decode_image(jpeg), training_images[0])


def test_cache_decodes_each_image_once_then_needs_no_jpeg(tmp_path: Path) -> None:
    copy = tmp_path / "lake"
    shutil.copytree(LAKE, copy)
    samples = expand(default_recipe_for([copy]))  # 3 cameras x 2 flips per row
    cache = ImageCache(samples.unique_paths)
    batches = DrivingBatches(samples, cache, batch_size=64, shuffle=True,
                             augment=AugmentConfig(), seed=1)
    first_epoch = [batches[index] for index in range(len(batches))]
    assert cache.decode_count == len(samples.unique_paths) == len(samples) // 2
    batches.on_epoch_end()

    shutil.rmtree(copy / "IMG")  # no JPEG left on disk
    second_epoch = [batches[index] for index in range(len(batches))]
    assert cache.decode_count == len(samples.unique_paths)
    assert sum(len(steering) for _, steering in second_epoch) == len(samples)
    # A new epoch reshuffles (and re-augments) but draws from the same samples.
    assert not np.array_equal(first_epoch[0][1], second_epoch[0][1])
    np.testing.assert_allclose(
        np.sort(np.abs(np.concatenate([s for _, s in first_epoch]))).sum(),
        np.sort(np.abs(np.concatenate([s for _, s in second_epoch]))).sum(), rtol=0.2,
    )


def test_cache_fill_skips_bad_files_and_memmap_lives_in_the_folder(tmp_path: Path) -> None:
    good = sorted((LAKE / "IMG").glob("center_*.jpg"))[:3]
    corrupt = tmp_path / "corrupt.jpg"
    corrupt.write_bytes(good[0].read_bytes()[:200])
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((10, 20, 3), np.uint8))
    paths = [*good, corrupt, tmp_path / "missing.jpg", small]
    cache = ImageCache(paths, memmap_path=tmp_path / "cache.u8", memory_limit_bytes=0)
    assert cache.memmap_path == tmp_path / "cache.u8" and cache.memmap_path.is_file()
    failed = cache.fill(workers=2)
    assert {index: error.reason for index, error in failed.items()} == {
        3: "image_corrupt", 4: "image_missing", 5: "image_size"
    }
    assert "missing.jpg" in str(failed[4]) and "20x10" in str(failed[5])
    np.testing.assert_array_equal(cache.get(np.array([1]))[0], read_rgb(good[1]))
    with pytest.raises(ImageDecodeError, match="does not decode"):
        cache.get(np.array([0, 3]))
    cache.close(delete=True)
    assert not (tmp_path / "cache.u8").exists()


def _resident_pages(path: Path) -> int:
    """Pages of the file at ``path`` mapped into this process and resident (/proc/self/smaps)."""
    resident, inside = 0, False
    for line in Path("/proc/self/smaps").read_text().splitlines():
        if line[:1].isdigit() or line[:1] in "abcdef":
            inside = line.rstrip().endswith(str(path))
        elif inside and line.startswith("Rss:"):
            resident += int(line.split()[1]) // 4
    return resident


def test_a_memmap_cache_lets_go_of_its_pages_and_keeps_its_frames(tmp_path: Path,
                                                                   monkeypatch) -> None:
    """Past MAPPED_BYTES_LIMIT of frames written, the process drops the memmap's pages
    (its resident memory does not grow with the cache); reads map nothing and give the same
    frames."""
    from clonedrive.data import batches

    paths = sorted((LAKE / "IMG").glob("*.jpg"))[:12]
    cache = ImageCache(paths, memmap_path=tmp_path / "cache.u8", memory_limit_bytes=0)
    frame_pages = cache.frame_bytes // 4096
    monkeypatch.setattr(batches, "MAPPED_BYTES_LIMIT", 3 * cache.frame_bytes)
    cache.fill(workers=1)
    assert cache.mapped_bytes <= 3 * cache.frame_bytes  # released on the way
    assert _resident_pages(cache.memmap_path) <= 4 * (frame_pages + 1)
    for index in (0, 5, 11, 7):
        np.testing.assert_array_equal(cache.get(np.array([index]))[0], read_rgb(paths[index]))
    np.testing.assert_array_equal(cache.get(np.arange(12)),
                                  np.stack([read_rgb(path) for path in paths]))
    assert _resident_pages(cache.memmap_path) <= 16 * (frame_pages + 1)
    in_memory = ImageCache(paths)  # an in-memory cache has nothing to let go of
    in_memory.fill(workers=1)
    assert in_memory.mapped_bytes == 0
    cache.close(delete=True)


def test_batches_shapes_flips_weights_and_order(tmp_path: Path) -> None:
    recipe = parse_recipe(f'[[recording]]\npath = "{LAKE.as_posix()}"\ncameras = "center"\n'
                          "weight = 2.5\n")
    samples = expand(recipe)  # each center frame and its mirrored copy
    cache = ImageCache(samples.unique_paths)
    plain = DrivingBatches(samples, cache, batch_size=32)
    assert len(plain) == int(np.ceil(len(samples) / 32))
    images, steering, weight = plain[0]
    assert images.dtype == np.uint8 and images.shape == (32, 160, 320, 3)
    assert steering.dtype == np.float32 and steering.shape == (32,)
    assert np.all(weight == 2.5)
    # Sample 1 is the mirrored copy of sample 0.
    assert samples.flip[1] and samples.steering[1] == -samples.steering[0] + 0.0
    np.testing.assert_array_equal(images[1], images[0][:, ::-1])
    np.testing.assert_array_equal(images[0], read_rgb(samples.image_path(0)))
    last_images, last_steering, _ = plain[len(plain) - 1]
    assert len(last_steering) == len(samples) - 32 * (len(plain) - 1)

    shuffled = DrivingBatches(samples, cache, batch_size=32, shuffle=True, seed=4, epoch=2)
    again = DrivingBatches(samples, cache, batch_size=32, shuffle=True, seed=4, epoch=2)
    np.testing.assert_array_equal(shuffled.batch_indices(0), again.batch_indices(0))
    order = np.concatenate([shuffled.batch_indices(i) for i in range(len(shuffled))])
    np.testing.assert_array_equal(np.sort(order), np.arange(len(samples)))
    with pytest.raises(IndexError):
        shuffled[len(shuffled)]



def test_a_cache_of_the_rows_training_reads_gives_the_same_batches(tmp_path: Path) -> None:
    """A cache keeping only the rows a cropping network and its augmentation read is less than
    half the size, and the batches' visible rows are the same to the bit."""
    from clonedrive.data.augment import BLUR_MARGIN
    from clonedrive.data.dataset import cached_rows
    from clonedrive.model.train_config import TrainConfig

    samples = expand(default_recipe_for([LAKE]))
    visible = (60, 160 - 25)
    whole = ImageCache(samples.unique_paths)
    whole.fill()
    plain = cached_rows(TrainConfig(crop_top_px=60).dataset_config())
    assert plain[0] <= visible[0] - 6 and plain[1] >= visible[1] + 6
    # Looks blur: the rows its kernel reaches beyond a shifted window are cached too.
    looks = cached_rows(TrainConfig(crop_top_px=60, augment_looks=0.5).dataset_config())
    assert looks == (plain[0] - BLUR_MARGIN, plain[1] + BLUR_MARGIN)
    for rows, augment in ((plain, AugmentConfig()),
                          (looks, AugmentConfig(looks_probability=0.5, blur_probability=1.0))):
        cropped = ImageCache(samples.unique_paths, rows=rows, memmap_path=tmp_path / "c.u8",
                             memory_limit_bytes=0)
        assert cropped.nbytes < 0.6 * whole.nbytes
        assert (tmp_path / "c.u8").stat().st_size == cropped.nbytes
        cropped.fill()
        options = {"batch_size": 16, "shuffle": True, "augment": augment, "seed": 4,
                   "rows": visible}
        expected = DrivingBatches(samples, whole, **options)
        got = DrivingBatches(samples, cropped, **options)
        for index in range(len(expected)):
            (images_a, labels_a), (images_b, labels_b) = expected[index], got[index]
            np.testing.assert_array_equal(images_a[:, visible[0]:visible[1]],
                                          images_b[:, visible[0]:visible[1]])
            np.testing.assert_array_equal(labels_a, labels_b)
        frame = cropped.get(np.array([0]))[0]
        assert frame.shape == (160, 320, 3) and not frame[: rows[0]].any()
        cropped.close()
        assert not (tmp_path / "c.u8").exists()
