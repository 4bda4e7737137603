"""Rows of a recording written behind the simulator: each row only once its three images are in
place, in step order, by one background thread.

:class:`RowSink` JPEG-encodes a step's three camera images, writes each to a temporary name and
renames it into ``IMG/`` (:data:`TEMP_SUFFIX`), then appends the row to ``driving_log.csv``
(:mod:`clonedrive.data.log_writer`) and, for a labelled step, the expert's speed label to
``target_speed.csv`` (:mod:`clonedrive.data.speed_labels`) before it. A process killed at any
moment leaves a log whose every row's images exist and decode. Used by ``record``
(:mod:`clonedrive.data.recorder`), manual driving (:mod:`clonedrive.manual.recording`) and DAgger.
"""

from __future__ import annotations

import os
import queue
import threading
from datetime import datetime
from pathlib import Path

import numpy as np

from clonedrive.base.output_files import clear_temporary, open_output
from clonedrive.base.paths import describe_os_error, with_filename
from clonedrive.base.udacity_spec import JPEG_QUALITY
from clonedrive.data.driving_log import CAMERAS, IMAGE_FOLDER, image_name
from clonedrive.data.log_writer import DrivingLogWriter
from clonedrive.data.speed_labels import SpeedLabelWriter

#: Steps queued for the writer thread at most (bounds memory; each holds three images).
MAX_PENDING_ROWS = 16
#: Suffix of an image being written (``IMG/.center_..._123.tmp.jpg``), renamed when complete.
TEMP_SUFFIX = ".tmp.jpg"


class RowSink:
    """Writes rows in step order, each only after its three images are in place.

    One background thread owns the images and the CSV: for each submitted step, in order, it
    JPEG-encodes and writes the three images (temp name, then rename), then appends the row. The
    main thread meanwhile renders the next frame (Panda3D and OpenCV release the GIL).
    ``submit`` blocks when ``MAX_PENDING_ROWS`` steps are waiting; ``close`` writes the rest.
    Image names follow ``start`` plus each observation's simulated ``time_s`` (see
    :func:`clonedrive.data.log_folder.prepare_log_folder` for a start that continues an
    existing log). Used by :func:`clonedrive.data.recorder.record` and by manual driving
    (:mod:`clonedrive.manual.recording`).
    """

    def __init__(self, out: Path, start: datetime, *, header: bool = False,
                 relative_paths: bool = False, jpeg_quality: int = JPEG_QUALITY,
                 fsync_every_rows: int = 15) -> None:
        if not 1 <= jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in [1, 100], got {jpeg_quality}")
        if fsync_every_rows < 1:
            raise ValueError("fsync_every_rows must be at least 1")
        self.image_dir = out / IMAGE_FOLDER
        self.start = start
        self.jpeg_quality = int(jpeg_quality)
        self.fsync_every_rows = int(fsync_every_rows)
        self.writer = DrivingLogWriter(out, header=header, relative_paths=relative_paths,
                                       fsync=False)
        self._sync_fd = os.open(self.writer.csv_path, os.O_RDONLY)
        self.labels: SpeedLabelWriter | None = None  # opened with the first labelled row
        self._queue: queue.Queue = queue.Queue(maxsize=MAX_PENDING_ROWS)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._work, name="record-writer", daemon=True)
        self._thread.start()

    @property
    def rows_written(self) -> int:
        return self.writer.rows_written

    def submit(self, obs, steering: float, controls, *, target_speed_mph: float | None = None
               ) -> tuple[str, str, str]:
        """Queue one step's row: ``obs``'s three images and speed, the ``steering`` label and
        the applied ``controls`` (throttle recorded clipped to >= 0, brake as applied), and
        with ``target_speed_mph`` the expert's speed label (``target_speed.csv``, written
        before the row). Returns the three image names."""
        if self._error is not None:
            raise RecordingWriteError(_write_failure(self._error)) from self._error
        missing = [camera for camera in CAMERAS if camera not in obs.images]
        if missing:
            raise RuntimeError(f"the simulator rendered no {', '.join(missing)} image(s)")
        names = tuple(image_name(camera, self.start, obs.time_s) for camera in CAMERAS)
        images = tuple(obs.images[camera] for camera in CAMERAS)
        values = (float(steering), max(controls.throttle, 0.0), controls.brake,
                  max(obs.speed_mph, 0.0))
        label = None if target_speed_mph is None else float(target_speed_mph)
        self._queue.put((images, names, values, label))
        return names

    def _work(self) -> None:
        import cv2

        params = [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality]
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self._error is not None:
                continue  # keep consuming so that submit never blocks forever
            images, names, values, label = item
            try:
                paths = [self.image_dir / name for name in names]
                for image, path in zip(images, paths, strict=True):
                    write_jpeg(image, path, params)
                if label is not None:
                    if self.labels is None:
                        self.labels = SpeedLabelWriter(self.writer.folder)
                    self.labels.append(names[0], label)
                self.writer.append(*paths, *values)
                if self.writer.rows_written % self.fsync_every_rows == 0:
                    self._sync()
            except BaseException as error:  # handed to the main thread by submit/close
                self._error = error

    def close(self) -> None:
        """Write every queued row, then sync and close the CSV. Raises a writing error."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        if self._sync_fd >= 0:
            self._sync()
            os.close(self._sync_fd)
            self._sync_fd = -1
        self.writer.close()
        if self.labels is not None:
            self.labels.close()
        if self._error is not None:
            raise RecordingWriteError(_write_failure(self._error)) from self._error

    def _sync(self) -> None:
        if self.labels is not None:
            os.fsync(self.labels.fileno())
        try:
            os.fsync(self._sync_fd)
        except OSError as error:  # ENOSPC names no file: name the log
            raise with_filename(error, self.writer.csv_path) from None

    def __enter__(self) -> RowSink:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def write_jpeg(image_rgb: np.ndarray, path: Path, params: list[int]) -> None:
    """Write an RGB image as a JPEG atomically: encode in memory, write a temp name, rename.
    A full disk or a read-only folder raises ``OSError`` naming the file."""
    import cv2

    temp = path.with_name(f".{path.stem}{TEMP_SUFFIX}")
    # OpenCV encodes BGR: the reversed channel view is copied by the binding, not re-encoded.
    ok, encoded = cv2.imencode(".jpg", image_rgb[:, :, ::-1], params)
    if not ok:
        raise RuntimeError(f"OpenCV could not encode the image for {path}")
    try:
        with open_output(clear_temporary(temp), "wb") as handle:
            handle.write(encoded.data)
        os.replace(temp, path)
    except OSError as error:  # named by the image the log refers to, not the temporary name
        temp.unlink(missing_ok=True)
        if error.errno is None:
            raise
        raise OSError(error.errno, error.strerror, str(path)) from None


class RecordingWriteError(RuntimeError):
    """Writing the recording failed (a full disk, a read-only folder...); every row written
    before is whole. The message is one line naming the file."""


def _write_failure(error: BaseException) -> str:
    if isinstance(error, OSError):
        return f"writing the log failed: {describe_os_error(error)}"
    return f"writing the log failed: {error}"
