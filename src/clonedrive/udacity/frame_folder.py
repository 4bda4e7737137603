"""The drive server's image folder: the frames it receives, saved as ``drive.py`` saves them.

``drive.py model.h5 run1`` writes each received center-camera JPEG into ``run1`` under its UTC
time, ``YYYY_MM_DD_HH_MM_SS_mmm.jpg``, for ``video.py`` to turn into a video. :class:`FrameFolder`
does the same with two differences that keep the server safe to leave running: it never deletes
what the folder held (frames are added to it), and it stops saving once the folder holds
``max_mb`` megabytes, counted from what was there at start, with one warning (driving goes on).

It is its own module because it is its own concern: a file name scheme, a disk cap and atomic
writes, none of which the protocol or the connection handling needs to know.
"""

from __future__ import annotations

import logging
import os
import time
from datetime import UTC, datetime
from pathlib import Path

from clonedrive.base.config import write_bytes_atomic
from clonedrive.base.output_files import probe_writable

logger = logging.getLogger("clonedrive.udacity")


class FrameFolder:
    """Saves received JPEG frames into ``folder``, at most ``max_mb`` megabytes in all.

    Call :meth:`prepare` once before serving (it creates the folder and measures it), then
    :meth:`save` for each frame, from one thread at a time (the server's policy thread).
    """

    def __init__(self, folder: Path, max_mb: float) -> None:
        self.folder = folder
        self.max_mb = max_mb
        self.saved = 0  #: frames written
        self.over_cap = 0  #: frames not written because the folder was full
        self._bytes = 0  # in the folder: what was there at start plus what was saved
        self._cap_reported = False
        self._last_ms = 0

    def prepare(self) -> None:
        """Create the folder if needed and count what it holds (:func:`prepare_image_folder`)."""
        self._bytes = prepare_image_folder(self.folder)

    def save(self, jpeg: bytes) -> str | None:
        """Write one frame (atomically) under the next free name; over the cap, count it and do
        nothing. Returns why the frame could not be written (an OS error), else None."""
        if self._bytes + len(jpeg) > self.max_mb * 1e6:
            self.over_cap += 1
            if not self._cap_reported:
                self._cap_reported = True
                logger.warning("image folder %s holds %.0f MB, its cap is %g MB "
                               "(--image-folder-max-mb): received frames are no longer saved",
                               self.folder, self._bytes / 1e6, self.max_mb)
            return None
        path = self.folder / self._next_name()
        try:
            write_bytes_atomic(path, jpeg)
        except OSError as error:
            return f"cannot save {path}: {error}"
        self._bytes += len(jpeg)
        self.saved += 1
        return None

    def _next_name(self) -> str:
        """``YYYY_MM_DD_HH_MM_SS_mmm.jpg`` (UTC), strictly increasing: a frame within the same
        millisecond as the one before gets the next millisecond."""
        now_ms = max(time.time_ns() // 1_000_000, self._last_ms + 1)
        self._last_ms = now_ms
        stamp = datetime.fromtimestamp(now_ms // 1000, tz=UTC)
        return f"{stamp:%Y_%m_%d_%H_%M_%S}_{now_ms % 1000:03d}.jpg"


def prepare_image_folder(folder: Path) -> int:
    """Create ``folder`` if needed, check that frames can be written there, and return the
    bytes its files hold already. Raises ``ValueError`` naming the folder (not a socket
    error) when it is a file or cannot be written."""
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"image folder {folder} is an existing file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe_writable(folder, f".write-test-{os.getpid()}")
    except OSError as error:
        raise ValueError(f"image folder {folder}: cannot write there ({error.strerror})") from None
    total = 0
    with os.scandir(folder) as entries:
        for entry in entries:
            if entry.is_file(follow_symlinks=False):
                total += entry.stat(follow_symlinks=False).st_size
    return total
