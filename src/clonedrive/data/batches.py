"""Training batches: a decoded-image cache and a ``keras.utils.PyDataset`` over samples.

Images are RGB end to end. JPEGs are decoded with OpenCV (which returns BGR) and converted
to RGB at once, exactly as the drive server turns a received JPEG into the network's input,
so the network sees identical pixels in training and in driving.

Each distinct image file is decoded once into a uint8 array (in memory, or an ``np.memmap``
file when it would be large); every later epoch reads the cache and decodes no JPEG.
"""

from __future__ import annotations

import errno
import math
import mmap
import os
import shutil
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from clonedrive.base.images import ImageDecodeError
from clonedrive.base.images import read_rgb as read_image_file
from clonedrive.base.keras_backend import import_keras
from clonedrive.base.paths import with_filename
from clonedrive.base.udacity_spec import IMAGE_SHAPE as FRAME_SHAPE
from clonedrive.data.augment import AugmentConfig, augment_batch
from clonedrive.data.recipe import Samples
from clonedrive.network.contract import SPEED_OUTPUT, STEERING_OUTPUT, TARGET_SPEED_SCALE_MPH

keras = import_keras()

FRAME_BYTES = int(np.prod(FRAME_SHAPE))
#: Caches larger than this go to a memmap file when a folder for it is given, bytes.
DEFAULT_MEMORY_LIMIT_BYTES = 2 * 1024**3
#: A memmap cache's frames written since the mapping was last released, at most: then the
#: process lets go of its pages (they stay in the OS page cache, written ones included), so its
#: resident memory does not grow with the cache's size. Frames are read back with ``pread``,
#: which maps nothing.
MAPPED_BYTES_LIMIT = 512 * 1024**2


def read_rgb(path: str | os.PathLike, out: np.ndarray | None = None) -> np.ndarray:
    """Read a camera image file as uint8 RGB (160, 320, 3); ``ImageDecodeError`` if unusable."""
    return read_image_file(path, out, shape=FRAME_SHAPE)


def reserved_memmap(path: Path, shape: tuple[int, ...]) -> np.memmap:
    """A new uint8 ``np.memmap`` file of ``shape`` whose disk blocks are reserved before it is
    mapped. Writing into a mapping past a full disk does not fail: the kernel kills the
    process with SIGBUS, with no message. So the free space is checked first (an ``OSError``
    ENOSPC naming the path, the need and what is free), then the blocks are allocated
    (``posix_fallocate``; where the file system cannot, the check stands alone)."""
    need = math.prod(shape)
    path.parent.mkdir(parents=True, exist_ok=True)
    free = shutil.disk_usage(path.parent).free + (path.stat().st_size if path.is_file() else 0)
    if need > free:
        raise OSError(errno.ENOSPC, f"no space left on device for the image cache: it needs "
                      f"{need / 2**20:,.1f} MiB, {free / 2**20:,.1f} MiB are free", str(path))
    with open(path, "wb") as handle:
        try:
            if need:
                os.posix_fallocate(handle.fileno(), 0, need)
        except OSError as error:
            if error.errno not in (errno.EOPNOTSUPP, errno.EINVAL):
                handle.close()
                path.unlink(missing_ok=True)
                raise with_filename(error, path) from None
    return np.memmap(path, dtype=np.uint8, mode="r+", shape=shape)


class ImageCache:
    """Decoded uint8 RGB frames of ``paths``, decoded at most once each.

    Lives in memory, or in ``memmap_path`` (created, overwritten) when the frames would take
    more than ``memory_limit_bytes``. ``decode_count`` counts JPEG decodes. A memmap is filled
    through its mapping, at most about :data:`MAPPED_BYTES_LIMIT` of it mapped at a time, and
    read with ``pread``: the process's resident memory does not grow with the cache.

    ``rows`` = ``(first, end)``: keep only those rows of each frame (the rows a cropping
    network and its augmentation read); :meth:`get` still returns whole frames, the other
    rows 0. A network that sees 75 of 160 rows needs less than half the cache.
    """

    def __init__(
        self,
        paths: Sequence[Path],
        *,
        memmap_path: str | os.PathLike | None = None,
        memory_limit_bytes: int = DEFAULT_MEMORY_LIMIT_BYTES,
        rows: tuple[int, int] | None = None,
    ) -> None:
        self.paths = list(paths)
        first, end = (0, FRAME_SHAPE[0]) if rows is None else (int(rows[0]), int(rows[1]))
        if not 0 <= first < end <= FRAME_SHAPE[0]:
            raise ValueError(f"rows {rows} outside the frame's {FRAME_SHAPE[0]} rows")
        self.rows = (first, end)
        shape = (len(self.paths), end - first, *FRAME_SHAPE[1:])
        frame_bytes = FRAME_BYTES * (end - first) // FRAME_SHAPE[0]
        self.memmap_path: Path | None = None
        self._reader: int | None = None  #: a memmap's file, opened for pread
        if memmap_path is not None and len(self.paths) * frame_bytes > memory_limit_bytes:
            self.memmap_path = Path(memmap_path)
            self.frames = reserved_memmap(self.memmap_path, shape)
            self._reader = os.open(self.memmap_path, os.O_RDONLY)
        else:
            self.frames = np.empty(shape, dtype=np.uint8)
        self.frame_bytes = frame_bytes
        self.mapped_bytes = 0  #: bytes of a memmap written since its last release
        self.filled = np.zeros(len(self.paths), dtype=bool)
        self.failed: dict[int, ImageDecodeError] = {}  # index -> why it cannot be used
        self.decode_count = 0
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self.paths)

    @property
    def nbytes(self) -> int:
        return int(self.frames.nbytes)

    def _decode(self, index: int) -> bool:
        first, end = self.rows
        try:
            if (first, end) == (0, FRAME_SHAPE[0]):
                read_rgb(self.paths[index], out=self.frames[index])
            else:
                self.frames[index] = read_rgb(self.paths[index])[first:end]
        except ImageDecodeError as error:
            with self._lock:
                self.decode_count += 1
                self.failed[index] = error
            return False
        with self._lock:
            self.decode_count += 1
            self.filled[index] = True
        self._wrote(1)
        return True

    def _wrote(self, frames: int) -> None:
        """Count ``frames`` written; past :data:`MAPPED_BYTES_LIMIT`, release a memmap's pages
        from this process (``MADV_DONTNEED``: a shared file mapping keeps its data in the page
        cache, written pages included)."""
        if self.memmap_path is None or not isinstance(self.frames, np.memmap):
            return
        with self._lock:
            self.mapped_bytes += frames * self.frame_bytes
            if self.mapped_bytes <= MAPPED_BYTES_LIMIT:
                return
            self.mapped_bytes = 0
            self.frames.base.madvise(mmap.MADV_DONTNEED)

    def fill(self, *, workers: int = 2, progress: bool = False) -> dict[int, ImageDecodeError]:
        """Decode every frame not yet cached (OpenCV decodes outside the GIL, so threads
        help); returns ``{index: error}`` for the files that could not be used."""
        todo = [int(index) for index in np.flatnonzero(~self.filled) if index not in self.failed]
        bar = None
        if progress and todo:
            from clonedrive.base.progress import progress_bar

            bar = progress_bar(total=len(todo), desc="decoding images", unit="img")
        with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
            for _ in pool.map(self._decode, todo, chunksize=64):
                if bar is not None:
                    bar.update()
        if bar is not None:
            bar.close()
        return dict(self.failed)

    def get(self, indices: np.ndarray) -> np.ndarray:
        """The frames at ``indices`` as a new (len, 160, 320, 3) uint8 array (rows outside
        ``rows`` 0), decoding any not cached yet. Raises ``ImageDecodeError`` for an unusable
        file."""
        indices = np.asarray(indices, dtype=np.int64)
        for index in np.unique(indices[~self.filled[indices]]):
            if int(index) in self.failed or not self._decode(int(index)):
                raise self.failed[int(index)]
        first, end = self.rows
        cached = self._read(indices)
        if (first, end) == (0, FRAME_SHAPE[0]):
            return cached
        frames = np.zeros((len(indices), *FRAME_SHAPE), dtype=np.uint8)
        frames[:, first:end] = cached
        return frames

    def _read(self, indices: np.ndarray) -> np.ndarray:
        """The cached rows of the frames at ``indices``, a new array; from a memmap's file with
        ``pread`` (what the mapping wrote is in the same page cache), so nothing is mapped."""
        if self._reader is None:
            return self.frames[indices]
        cached = np.empty((len(indices), *self.frames.shape[1:]), dtype=np.uint8)
        for row, index in enumerate(indices):
            offset = (int(index) % len(self.paths)) * self.frame_bytes  # -1: the last, as numpy
            if os.preadv(self._reader, [cached[row]], offset) != self.frame_bytes:
                raise OSError(f"{self.memmap_path}: the image cache is shorter than it was made")
        return cached

    def close(self, *, delete: bool = True) -> None:
        """Release the memmap (and delete its file if ``delete``)."""
        if self._reader is not None:
            os.close(self._reader)
            self._reader = None
        if self.memmap_path is not None:
            if isinstance(self.frames, np.memmap):
                self.frames.flush()
            # Dropping the last reference unmaps the file (batches hold copies, not views).
            self.frames = np.empty((0, *self.frames.shape[1:]), dtype=np.uint8)
            self.filled = np.zeros(0, dtype=bool)
            if delete:
                self.memmap_path.unlink(missing_ok=True)


class DrivingBatches(keras.utils.PyDataset):
    """Batches ``(images, steering[, weight])`` of ``samples`` for ``model.fit``.

    ``images``: (N, 160, 320, 3) uint8 RGB (the models cast to float32 themselves);
    ``steering``: (N,) float32 in [-1, 1]; ``weight`` (N,) float32 only when some recording's
    weight is not 1. With ``speed_head`` the labels are a dict ``{"steering": (N,),
    "target_speed": (N,)}``, the speed label divided by ``TARGET_SPEED_SCALE_MPH``. With
    ``shuffle`` the order is a permutation drawn from
    ``(seed, epoch)``; with ``augment`` each batch is augmented with a generator drawn from
    ``(seed, epoch, batch index)``, so results do not depend on worker timing and a resumed
    run sees the same batches it would have seen. ``epoch`` advances in ``on_epoch_end``.

    ``rows`` = ``(first, end)``: the rows of the frame the network looks at (its crop). Set,
    augmentation computes only those rows, with the same values, and leaves the others 0, so
    training is the same at a third of the work (``model.train`` sets it from the network).

    ``partners`` (``(len(samples),)`` indices into ``samples``, e.g.
    :func:`clonedrive.data.neighbours.next_frames`): every batch is its N samples followed by
    their N partners, each pair augmented alike, labels (and weights) in the same order, for the
    consistency loss of ``train --consistency``.
    """

    def __init__(
        self,
        samples: Samples,
        cache: ImageCache,
        *,
        batch_size: int,
        shuffle: bool = False,
        augment: AugmentConfig | None = None,
        seed: int = 0,
        epoch: int = 0,
        workers: int = 1,
        max_queue_size: int = 4,
        speed_head: bool = False,
        rows: tuple[int, int] | None = None,
        partners: np.ndarray | None = None,
    ) -> None:
        super().__init__(workers=workers, use_multiprocessing=False, max_queue_size=max_queue_size)
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        if len(samples) == 0:
            raise ValueError("no samples to batch")
        self.samples = samples
        self.cache = cache
        self.batch_size = int(batch_size)
        self.shuffle = shuffle
        self.augment = augment
        self.seed = int(seed)
        self.with_weights = bool(np.any(samples.weight != 1.0))
        self.speed_head = bool(speed_head)
        self.rows = rows
        if partners is not None:
            partners = np.asarray(partners, dtype=np.int64)
            if partners.shape != (len(samples),) or (
                    len(partners) and not 0 <= partners.min() <= partners.max() < len(samples)):
                raise ValueError(f"partners: expected {len(samples)} indices into the samples")
        self.partners = partners
        self.epoch = int(epoch)
        self._order = self._make_order()

    def _make_order(self) -> np.ndarray:
        if not self.shuffle:
            return np.arange(len(self.samples))
        return np.random.default_rng([self.seed, self.epoch]).permutation(len(self.samples))

    def __len__(self) -> int:
        return math.ceil(len(self.samples) / self.batch_size)

    def batch_indices(self, index: int) -> np.ndarray:
        """Indices into ``samples`` of batch ``index`` in the current epoch."""
        if not 0 <= index < len(self):
            raise IndexError(f"batch {index} out of range [0, {len(self)})")
        return self._order[index * self.batch_size : (index + 1) * self.batch_size]

    def __getitem__(self, index: int):
        chosen = self.batch_indices(index)
        if self.partners is not None:
            chosen = np.concatenate([chosen, self.partners[chosen]])
        images = self.cache.get(self.samples.image_index[chosen])
        steering = self.samples.steering[chosen]
        mirrored = self.samples.flip[chosen]  # the recipe's flipped copies, labels negated
        if self.augment is not None:
            rng = np.random.default_rng([self.seed, self.epoch, index])
            images, steering = augment_batch(
                images, steering, rng, self.augment, mirror=mirrored, rows=self.rows,
                pairs=self.partners is not None,
            )
        else:
            for position in np.flatnonzero(mirrored):
                images[position] = cv2.flip(images[position], 1)
        labels = np.asarray(steering, dtype=np.float32)
        if self.speed_head:
            speed = self.samples.target_speed_mph[chosen] / np.float32(TARGET_SPEED_SCALE_MPH)
            labels = {STEERING_OUTPUT: labels, SPEED_OUTPUT: speed.astype(np.float32)}
        if self.with_weights:
            return images, labels, self.samples.weight[chosen]
        return images, labels

    def on_epoch_end(self) -> None:
        self.epoch += 1
        self._order = self._make_order()
