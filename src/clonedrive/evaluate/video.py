"""H.264 videos of driving: a folder of frames (as Udacity's video.py) or frames one at a time,
and stills read back from a video (the one reader of videos: the report uses it).

Encoding uses the ffmpeg binary shipped with ``imageio-ffmpeg`` (libx264, yuv420p, mp4, the
format every player accepts). Files are written under a temporary name and renamed when
complete, so a video on disk is never half-written.

Encoding runs off the caller's loop: :class:`VideoWriter` hands frames to a feeder thread (a
bounded queue, so memory stays bounded) that composes them, if given a callable, and pipes
them to ffmpeg, which encodes in its own process. The defaults are x264's ``ultrafast``
preset at imageio's quality 5 (CRF 25), the cheapest in CPU of the settings whose stills look
alike. Encoding shares the CPU with driving, so its cost is the evaluation's.

Two things cut ffmpeg's share:

- frames of even size are converted to YUV 4:2:0 on the feeder thread (OpenCV, BT.601 limited
  range as ffmpeg's own converter; 0.05-0.12 ms a frame, outside Python's lock) and piped as
  such: half the bytes, and no conversion in ffmpeg. Odd sizes go as RGB and ffmpeg scales them;
- x264 encodes on one thread (:data:`ENCODER_THREADS`): its frame threads cost CPU to hand
  work between them, and the driving loop, not the encoder, should have the other core.
"""

from __future__ import annotations

import errno
import logging
import os
import queue
import shutil
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clonedrive.base.images import ImageDecodeError, read_rgb
from clonedrive.base.output_files import clear_temporary
from clonedrive.base.udacity_spec import CONTROL_HZ

logger = logging.getLogger("clonedrive.video")

FRAME_SUFFIXES = (".jpg", ".jpeg", ".png")
#: Frames per second of a video made from a folder of frames (Udacity's video.py default).
FOLDER_FPS = 60.0
#: Frame rates a video may have [frames/s]: ffmpeg's mp4 writer fails far outside them (1e30
#: overflows its time base), and no player shows more than the upper one.
FPS_RANGE = (0.01, 1000.0)
#: x264 speed/size trade-off (``ultrafast`` ... ``veryslow``).
DEFAULT_PRESET = "ultrafast"
#: imageio-ffmpeg's quality, 1-10 (libx264 CRF = 51 * (1 - quality / 10): 5 is CRF 25).
DEFAULT_QUALITY = 5.0
#: Frames waiting for the encoder at most; a caller faster than the encoder then waits.
QUEUE_FRAMES = 32
#: x264's threads per video (one: the CPU is shared with driving; see the module).
ENCODER_THREADS = 1
_DONE = object()
#: Errors of writing a file that name the file system as the reason.
_FILE_SYSTEM_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES)
#: A disk with less free than this [bytes] is full to ffmpeg, which writes in blocks of MBs.
FULL_DISK_BYTES = 1 << 20


class VideoWriter:
    """Append uint8 RGB frames ``(H, W, 3)`` one at a time; :meth:`close` finishes the mp4.

    ``append`` takes a frame, or a callable that returns one: a callable is called on the
    feeder thread, so composing a frame (a HUD, an overlay) happens off the caller's loop too.
    The first frame fixes the size; later frames must match it. H.264 with yuv420p needs even
    sides: an odd width or height is stretched by ffmpeg's scaler to the next even number.
    An error on the feeder thread (a bad frame, ffmpeg failing) is raised by the next
    ``append`` or by ``close``. Use as a context manager: on an exception the partial file is
    removed.
    """

    def __init__(self, path: str | os.PathLike, fps: float = FOLDER_FPS, *,
                 quality: float = DEFAULT_QUALITY,
                 preset: str = DEFAULT_PRESET) -> None:
        check_fps(fps)
        self.path = Path(path)
        self.fps = float(fps)
        self.quality = float(quality)
        self.preset = preset
        self.frames_written = 0
        self.size: tuple[int, int] | None = None  # (width, height) in pixels
        self._temporary = self.path.with_name(
            f".{self.path.stem}.partial{self.path.suffix or '.mp4'}"
        )
        self._encoder = None
        self._yuv_input = False  # frames piped as YUV 4:2:0 (even sizes), else as RGB
        self._closed = False
        self._queue: queue.Queue = queue.Queue(maxsize=QUEUE_FRAMES)
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._dropping = False

    def append(self, frame_rgb: np.ndarray | Callable[[], np.ndarray]) -> None:
        if self._closed:
            raise ValueError(f"{self.path}: the video is closed")
        self._raise_feeder_error()
        if not callable(frame_rgb):
            frame_rgb = self._checked(frame_rgb)  # a bad frame fails here, at once
        if self._thread is None:
            self._thread = threading.Thread(target=self._feed, name=f"video:{self.path.name}",
                                            daemon=True)
            self._thread.start()
        self._queue.put(frame_rgb)

    def close(self) -> Path | None:
        """Finish the file and return its path; with no frame added, write nothing, return None.

        Safe to call twice and from ``finally`` blocks.
        """
        if self._closed:
            return self.path if self.path.exists() and self.frames_written else None
        self._closed = True
        self._stop_feeder()
        if self._error is not None:
            self._discard()
            self._raise_feeder_error()
        if self._encoder is None:
            logger.warning("%s: no frames, no video written", self.path)
            return None
        try:
            self._encoder.close()
            self._check_finished()
        except BaseException as error:
            named = self._named(error)
            self._temporary.unlink(missing_ok=True)
            raise named from None
        os.replace(self._temporary, self.path)
        return self.path

    def abort(self) -> None:
        """Stop encoding and remove the partial file."""
        self._closed = True
        self._stop_feeder(drop=True)
        self._discard()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type: object, exc: object, traceback: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # ------------------------------------------------------------------ feeder thread
    def _feed(self) -> None:
        import cv2

        while True:
            item = self._queue.get()
            if item is _DONE:
                return
            if self._error is not None or self._dropping:
                continue  # drain: the caller learns of an error at its next call
            try:
                frame = self._checked(item()) if callable(item) else item
                if self._encoder is None:
                    self._start(self.size)
                if self._yuv_input:
                    frame = cv2.cvtColor(frame, cv2.COLOR_RGB2YUV_I420)
                self._encoder.send(frame)
                self.frames_written += 1
            except BaseException as error:  # handed to the caller's thread, not swallowed
                self._error = error

    def _checked(self, frame_rgb: np.ndarray) -> np.ndarray:
        frame = np.asarray(frame_rgb)
        if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
            raise ValueError(
                f"expected a uint8 RGB frame (H, W, 3), got {frame.dtype} {frame.shape}"
            )
        height, width = frame.shape[:2]
        if self.size is None:
            self.size = (width, height)
        elif (width, height) != self.size:
            raise ValueError(
                f"frame {self.frames_written} is {width}x{height}, "
                f"the video is {self.size[0]}x{self.size[1]}"
            )
        return np.ascontiguousarray(frame)

    def _stop_feeder(self, *, drop: bool = False) -> None:
        if self._thread is None:
            return
        self._dropping = drop
        self._queue.put(_DONE)
        self._thread.join()
        self._thread = None

    def _raise_feeder_error(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise self._named(error)

    def _named(self, error: BaseException) -> BaseException:
        """``error`` of the encoder's as an ``OSError`` naming the video when the file system
        is why: ffmpeg dies on a full disk, and Python sees only a broken pipe (ffmpeg's own
        message goes to stderr, uncaptured), so a disk with next to nothing free counts as
        full."""
        if not isinstance(error, OSError | RuntimeError):
            return error
        number = getattr(error, "errno", None)
        if number not in _FILE_SYSTEM_ERRNOS:
            number = errno.ENOSPC if self._disk_full() else None
        if number is None:
            return error
        named = OSError(number, os.strerror(number), str(self.path))
        named.__cause__ = error
        return named

    def _disk_full(self) -> bool:
        try:
            return shutil.disk_usage(self.path.parent).free < FULL_DISK_BYTES
        except OSError:
            return False

    def _check_finished(self) -> None:
        """Raise unless the temporary file is a whole video of every frame sent: ffmpeg that
        fails to finish the file (a full disk while it writes the index) exits with an error
        that imageio-ffmpeg does not pass on."""
        import cv2

        capture = cv2.VideoCapture(str(self._temporary))
        try:
            frames = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) if capture.isOpened() else 0
        finally:
            capture.release()
        if frames == self.frames_written:
            return
        number = errno.ENOSPC if self._disk_full() else errno.EIO
        reason = os.strerror(number) if number == errno.ENOSPC else (
            f"ffmpeg did not finish the video ({frames} of {self.frames_written} frames "
            "readable; its message is above)")
        raise OSError(number, reason, str(self.path))

    def _discard(self) -> None:
        if self._encoder is None:
            return
        try:
            self._encoder.close()
        except OSError as error:  # ffmpeg's own failure; the partial file goes anyway
            logger.warning("%s: ffmpeg failed while aborting: %s", self.path, error)
        finally:
            self._encoder = None
            self._temporary.unlink(missing_ok=True)

    def _start(self, size: tuple[int, int]) -> None:
        import imageio_ffmpeg

        self.path.parent.mkdir(parents=True, exist_ok=True)
        clear_temporary(self._temporary)  # ffmpeg would write through a link planted there
        self._yuv_input = size[0] % 2 == 0 and size[1] % 2 == 0
        self._encoder = imageio_ffmpeg.write_frames(
            str(self._temporary),
            size,
            pix_fmt_in="yuv420p" if self._yuv_input else "rgb24",
            pix_fmt_out="yuv420p",
            fps=self.fps,
            quality=self.quality,
            codec="libx264",
            macro_block_size=2,
            output_params=["-preset", self.preset, "-threads", str(ENCODER_THREADS),
                           "-movflags", "+faststart"],
        )
        self._encoder.send(None)  # start ffmpeg


@dataclass
class VideoSummary:
    path: Path
    frames: int
    skipped: list[tuple[str, str]] = field(default_factory=list)  # (file name, reason)


def frame_files(folder: str | os.PathLike) -> list[Path]:
    """Image files in ``folder`` sorted by name (hidden files, e.g. partial writes, excluded)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"frame folder not found: {folder}")
    return sorted(
        path
        for path in folder.iterdir()
        if path.suffix.lower() in FRAME_SUFFIXES
        and not path.name.startswith(".")
        and path.is_file()
    )


def default_video_path(folder: str | os.PathLike) -> Path:
    """``run1/`` -> ``run1.mp4`` beside it, as Udacity's video.py names it."""
    folder = Path(folder).resolve()
    return folder.with_name(folder.name + ".mp4")


def check_fps(fps: float) -> None:
    """``ValueError`` naming :data:`FPS_RANGE` for a frame rate outside it (NaN too)."""
    low, high = FPS_RANGE
    if not low <= fps <= high:
        raise ValueError(f"fps must be in [{low:g}, {high:g}] frames per second, got {fps}")


@dataclass(frozen=True)
class VideoConfig:
    """What ``clonedrive video`` encodes: a folder of frames into an mp4."""

    fps: float = FOLDER_FPS  #: frames per second of the video
    out: str | None = None  #: the mp4 to write; None: ``FOLDER.mp4`` beside the folder

    def __post_init__(self) -> None:
        check_fps(self.fps)
        if self.out is not None and not str(self.out).strip():
            raise ValueError("out must name a file (or be left out for FOLDER.mp4)")


def encode_folder(
    folder: str | os.PathLike,
    fps: float = FOLDER_FPS,
    out: str | os.PathLike | None = None,
    *,
    progress: bool = False,
) -> VideoSummary:
    """Encode the frames of ``folder`` (sorted by name) into an mp4; skip and count bad frames.

    A frame that does not decode, or whose size differs from the first good frame, is skipped
    and reported in :attr:`VideoSummary.skipped`. Raises ``ValueError`` if no frame is usable.
    """
    from clonedrive.base.progress import progress_bar

    files = frame_files(folder)
    if not files:
        raise ValueError(f"{folder}: no frames ({', '.join(FRAME_SUFFIXES)} files) to encode")
    out_path = Path(out) if out is not None else default_video_path(folder)
    summary = VideoSummary(path=out_path, frames=0)
    writer = VideoWriter(out_path, fps)
    used = 0
    try:
        for path in progress_bar(files, desc="video", unit="frame", enabled=progress):
            try:
                rgb = read_rgb(path)
            except ImageDecodeError:
                summary.skipped.append((path.name, "does not decode"))
                continue
            height, width = rgb.shape[:2]
            if writer.size is not None and writer.size != (width, height):
                reason = f"size {width}x{height}, the video is {writer.size[0]}x{writer.size[1]}"
                summary.skipped.append((path.name, reason))
                continue
            writer.append(rgb)
            used += 1
        if used == 0:
            raise ValueError(f"{folder}: none of the {len(files)} frames could be decoded")
        writer.close()
    except BaseException:
        writer.abort()
        raise
    summary.frames = writer.frames_written
    for name, reason in summary.skipped:
        logger.warning("skipped frame %s: %s", name, reason)
    return summary


def frames_to_video(
    folder: str | os.PathLike, fps: float = FOLDER_FPS, out: str | os.PathLike | None = None
) -> Path:
    """Encode ``folder``'s frames (sorted by name) as H.264 yuv420p mp4; default ``FOLDER.mp4``."""
    return encode_folder(folder, fps, out).path


def read_stills(video_path: str | os.PathLike, count: int = 3) -> list[tuple[float, np.ndarray]]:
    """``count`` frames spread over a video (at 1/6, 1/2 and 5/6 of its length for three), as
    (time [s], uint8 RGB); empty if the video cannot be read.

    Frames are reached by seeking; if the decoder does not land on the asked frame, the video
    is read again from the start, skipping frames up to each one.
    """
    import cv2

    capture = cv2.VideoCapture(str(video_path))
    try:
        if not capture.isOpened():
            return []
        fps = capture.get(cv2.CAP_PROP_FPS) or CONTROL_HZ
        total = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        if total <= 0:
            return []
        wanted = sorted({min(total - 1, int((i + 0.5) * total / count)) for i in range(count)})
        stills = []
        for target in wanted:
            capture.set(cv2.CAP_PROP_POS_FRAMES, target)
            ok, frame = capture.read()
            if not ok or int(capture.get(cv2.CAP_PROP_POS_FRAMES)) != target + 1:
                break
            stills.append((target / fps, cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)))
        else:
            return stills
    finally:
        capture.release()
    return read_stills_in_order(video_path, wanted, fps)


def read_stills_in_order(video_path: str | os.PathLike, wanted: list[int], fps: float
                         ) -> list[tuple[float, np.ndarray]]:
    """Frames ``wanted`` (sorted indices) of a video as (time [s], uint8 RGB), reading from
    the start without seeking; stops early at the video's end."""
    import cv2

    capture = cv2.VideoCapture(str(video_path))
    try:
        stills = []
        index = 0
        for target in wanted:
            while index < target:  # grab() decodes but does not convert: cheaper than read()
                if not capture.grab():
                    return stills
                index += 1
            ok, frame = capture.read()
            index += 1
            if not ok:
                break
            stills.append((target / fps, cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)))
        return stills
    finally:
        capture.release()
