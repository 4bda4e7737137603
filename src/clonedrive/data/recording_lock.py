"""One writer per recording folder: a lock file that holds the writer's PID.

Two recorders writing into one folder interleave their rows and overwrite each other's images
(both exit 0, and the log looks fine). :class:`RecordingLock` makes the second one fail at once
with a message naming the first (its PID and when it started).

The lock is ``<folder>/.clonedrive-recording.lock``, a small JSON text (pid, host, started),
held with ``flock`` for as long as the recording runs. The kernel drops a ``flock`` when its
process dies, however it dies, so a lock file left behind by a killed recorder is recognised as
stale: the next recorder takes it over and says so (``RecordingLock.stale``). Where ``flock``
does not exist (Windows) the file is created exclusively, and an existing one is reported with
the advice to delete it if no recorder runs.
"""

from __future__ import annotations

import json
import logging
import os
import socket
from datetime import datetime
from pathlib import Path

from clonedrive.base.output_files import open_output_fd
from clonedrive.base.paths import with_filename

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None

LOCK_NAME = ".clonedrive-recording.lock"

logger = logging.getLogger(__name__)


class RecordingLockedError(ValueError):
    """Another recorder is writing into the folder; the message names it."""


class RecordingLock:
    """Hold the recording lock of ``folder`` (created if missing) while in a ``with`` block.

    ``acquire`` raises :class:`RecordingLockedError` when a live recorder holds it. ``stale``
    is the lock a dead recorder left (its content as a dict) when this one replaced it.
    A folder the lock created is removed again on release if nothing else was written to it.
    ``name``: the lock file's name in ``folder``; ``writer``: who holds it, and ``target``:
    what it writes (``folder`` unless given), as the second writer's error names them (other
    commands' outputs: :mod:`clonedrive.data.output_lock`).
    """

    def __init__(self, folder: str | os.PathLike, *, name: str = LOCK_NAME,
                 writer: str = "recorder", target: str | os.PathLike | None = None) -> None:
        self.folder = Path(folder)
        self.path = self.folder / name
        self.writer = writer
        self.target = Path(target) if target is not None else self.folder
        self.stale: dict | None = None
        self._fd: int | None = None
        self._created_folder = False

    def acquire(self) -> RecordingLock:
        if self._fd is not None:
            raise RuntimeError(f"{self.path}: already held by this object")
        self._created_folder = not self.folder.exists()
        self.folder.mkdir(parents=True, exist_ok=True)
        self._fd = self._acquire_flock() if fcntl is not None else self._acquire_exclusive()
        record = {"pid": os.getpid(), "host": socket.gethostname(), "writer": self.writer,
                  "started": datetime.now().isoformat(timespec="seconds")}
        try:
            os.ftruncate(self._fd, 0)
            os.write(self._fd, (json.dumps(record) + "\n").encode())
        except OSError as error:  # a full disk: say where, and leave no lock behind
            self.release()
            raise with_filename(error, self.path) from None
        if self.stale is not None:
            logger.warning("%s: took over a stale lock: %s PID %s (started %s) is no longer "
                           "running", self.path, _writer_of(self.stale, self.writer),
                           self.stale.get("pid", "?"), self.stale.get("started", "?"))
        return self

    def release(self) -> None:
        """Remove the lock file and let go (idempotent)."""
        if self._fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)  # while still holding it: no one can take it half
        finally:
            os.close(self._fd)
            self._fd = None
        if self._created_folder:
            try:
                self.folder.rmdir()  # only if empty: a recording that wrote nothing
            except OSError:
                pass

    def __enter__(self) -> RecordingLock:
        return self if self._fd is not None else self.acquire()  # held already: keep holding

    def __exit__(self, *exc_info: object) -> None:
        self.release()

    # ------------------------------------------------------------------ mechanisms

    def _acquire_flock(self) -> int:
        while True:
            fd = open_output_fd(self.path, os.O_RDWR | os.O_CREAT)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read_record(fd)
                os.close(fd)
                raise RecordingLockedError(self._locked_message(holder)) from None
            except BaseException:
                os.close(fd)
                raise
            # The holder may have removed the file between our open and our lock: then we
            # locked an unlinked file, and must try again on the one now at the path.
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            previous = _read_record(fd)
            if previous:
                self.stale = previous  # a lock file nobody holds: its recorder died
            return fd

    def _acquire_exclusive(self) -> int:
        try:
            return open_output_fd(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL)
        except FileExistsError:
            pass
        try:
            with open(self.path, "rb") as handle:
                holder = _parse_record(handle.read(4096))
        except FileNotFoundError:
            holder = {}
        raise RecordingLockedError(
            self._locked_message(holder) + f" (if none runs, delete {self.path})")

    def _locked_message(self, holder: dict) -> str:
        who = f"PID {holder.get('pid', '?')}"
        if holder.get("host") and holder.get("host") != socket.gethostname():
            who += f" on {holder['host']}"
        since = f", started {holder['started']}" if holder.get("started") else ""
        if self.writer == "recorder":
            return (f"{self.folder}: another recorder ({who}{since}) is writing into this "
                    "folder; wait for it to finish or record into another folder")
        return (f"{self.target}: another {_writer_of(holder, self.writer)} ({who}{since}) is "
                "writing there; wait for it to finish or choose another --out")


def _writer_of(record: dict, default: str) -> str:
    writer = record.get("writer")
    return writer if isinstance(writer, str) and writer.isprintable() else default


def _read_record(fd: int) -> dict:
    """The lock file's JSON content ({} if empty or unreadable)."""
    return _parse_record(os.pread(fd, 4096, 0))


def _parse_record(data: bytes) -> dict:
    try:
        record = json.loads(data.decode("utf-8", "replace") or "{}")
    except json.JSONDecodeError:
        return {"pid": "?"} if data.strip() else {}
    return record if isinstance(record, dict) else {}
