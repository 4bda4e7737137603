"""Open an output file without writing through a link someone planted at its name.

A folder a command writes into may already hold, at the name of one of its outputs, a symbolic
link to a file elsewhere (``driving_log.csv -> ~/.bashrc``), or a FIFO that would block the
writer forever. ``open()`` follows the link and appends to, or truncates, the other file.
:func:`open_output_fd` and :func:`open_output` open with ``O_NOFOLLOW`` and check that what they
opened is a regular file, so such a name is refused with :class:`RefusedOutputError`, one line
naming the path. Writers that replace a file (a temporary file in the same folder, then
``os.replace``) never write through a link at the final name; they call
:func:`clear_temporary` on the temporary name first, so that a link planted there is removed,
not followed.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path
from typing import IO

#: Never follow a symbolic link at the name opened (absent on Windows, where links are rare).
NO_FOLLOW = getattr(os, "O_NOFOLLOW", 0)
#: Opening a FIFO for writing must fail at once (ENXIO), not wait for a reader.
NO_BLOCK = getattr(os, "O_NONBLOCK", 0)
#: Permissions of a file created here, before the umask.
FILE_MODE = 0o644
LINK_REASON = "is a symbolic link; clonedrive does not write through a link at an output's name"
NOT_REGULAR_REASON = "is not a regular file (a FIFO, a device or a socket); clonedrive writes " \
                     "only regular files"
_MODES = {"w": os.O_WRONLY | os.O_CREAT | os.O_TRUNC,
          "a": os.O_WRONLY | os.O_CREAT | os.O_APPEND,
          "x": os.O_WRONLY | os.O_CREAT | os.O_EXCL}


class RefusedOutputError(OSError):
    """An output's name holds a symbolic link or something that is not a regular file; the
    message is one line naming the path (``errno`` is ``ELOOP``)."""

    def __init__(self, path: str | os.PathLike, reason: str) -> None:
        super().__init__(errno.ELOOP, reason, os.fspath(path))


def open_output_fd(path: str | os.PathLike, flags: int, mode: int = FILE_MODE) -> int:
    """``os.open(path, flags)`` refusing a symbolic link at ``path`` and anything but a regular
    file there (:class:`RefusedOutputError`); other errors are the usual ``OSError``."""
    try:
        fd = os.open(path, flags | NO_FOLLOW | NO_BLOCK | getattr(os, "O_BINARY", 0), mode)
    except OSError as error:
        if error.errno in (errno.ELOOP, errno.ENXIO) and _is_special(path):
            reason = LINK_REASON if os.path.islink(path) else NOT_REGULAR_REASON
            raise RefusedOutputError(path, reason) from None
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise RefusedOutputError(path, NOT_REGULAR_REASON)
    return fd


def open_output(path: str | os.PathLike, mode: str = "w", *, encoding: str | None = "utf-8"
                ) -> IO:
    """A file object for writing ``path`` (``mode``: ``w``, ``a`` or ``x``, plus ``b`` for
    bytes), opened by :func:`open_output_fd`."""
    binary = "b" in mode
    fd = open_output_fd(path, _MODES[mode.replace("b", "")])
    return os.fdopen(fd, mode.replace("x", "w"), encoding=None if binary else encoding)


def refuse_link(path: str | os.PathLike) -> None:
    """:class:`RefusedOutputError` if ``path`` is a symbolic link (a dangling one too)."""
    if os.path.islink(path):
        raise RefusedOutputError(path, LINK_REASON)


def clear_temporary(path: str | os.PathLike) -> Path:
    """Remove whatever file or link sits at the temporary name ``path`` (a link planted there
    would otherwise be written through), and return ``path``."""
    path = Path(path)
    try:
        path.unlink()
    except FileNotFoundError:
        pass
    return path


def _is_special(path: str | os.PathLike) -> bool:
    """Whether ``path`` itself (not what a link there points to) is not a regular file."""
    try:
        return not stat.S_ISREG(os.lstat(path).st_mode)
    except OSError:
        return False


def probe_writable(folder: str | os.PathLike, name: str) -> None:
    """Create and remove the empty file ``folder/name``: an ``OSError`` naming it when the
    folder cannot be written. Whatever sat at that name before (a planted link) is removed
    first, never written through."""
    probe = clear_temporary(Path(folder) / name)
    try:
        os.close(open_output_fd(probe, _MODES["x"]))
    finally:
        probe.unlink(missing_ok=True)
