"""File names made from user-given names, and the rule that every output stays inside --out.

A track's name, a run's name or a model's name is text a user (or a track file) chose: it may
hold ``..``, separators, a drive letter, NUL or thousands of characters. Only
:func:`safe_stem` turns such text into one path component, and :func:`inside` checks that a
path we are about to write lies inside the output folder.
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
from pathlib import Path

from clonedrive.base.output_files import probe_writable

#: Longest file-name stem we make [characters]; file systems allow 255 bytes per component.
MAX_STEM_CHARS = 80
_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]+")


def safe_stem(name: str, *, fallback: str = "unnamed") -> str:
    """One safe path component for ``name``: letters, digits and ``._+-`` only, no leading
    dot, at most :data:`MAX_STEM_CHARS`; ``:`` becomes ``_``. A name that had to lose other
    characters, or be shortened, gets a short hash of the original, so that two such names
    do not collapse to the same file.

    >>> safe_stem("gen:17"), safe_stem("lake"), safe_stem("../../etc/passwd")[:11]
    ('gen_17', 'lake', 'etc_passwd-')
    """
    text = str(name)
    readable = text.replace(":", "_")  # gen:17 -> gen_17, the one common harmless change
    stem = _UNSAFE.sub("_", readable).strip("._-")
    if not stem:
        stem = fallback
    if stem == readable and len(stem) <= MAX_STEM_CHARS:
        return stem
    digest = hashlib.sha1(text.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    return f"{stem[: MAX_STEM_CHARS - 9]}-{digest}"


def inside(folder: str | os.PathLike, path: str | os.PathLike) -> Path:
    """``path`` resolved, after checking that it lies inside ``folder``; ``ValueError`` when
    it would escape (through ``..``, an absolute path or a link)."""
    root = Path(folder).resolve()
    target = (root / path).resolve()
    if target != root and root not in target.parents:
        raise ValueError(f"{path}: refusing to write outside the output folder {root}")
    return target


def check_output_folder(path: str | os.PathLike, *, option: str = "--out") -> Path:
    """``path`` as a Path, after checking that it can be an output folder: a folder, or
    nothing yet. ``ValueError`` naming ``option`` when it is an existing file (or a link to
    one), or when a parent of it is a file."""
    path = Path(path)
    for candidate in (path, *path.parents):
        if candidate.exists() and not candidate.is_dir():
            where = "is" if candidate == path else f"is inside {candidate}, which is"
            raise ValueError(f"{option} {path} {where} an existing file, not a folder; give a "
                             "folder (new, or one this command wrote before)")
        if candidate.exists():
            break
    return path


def prepare_output_folder(path: str | os.PathLike, *, option: str = "--out") -> Path:
    """Create the output folder ``path`` (see :func:`check_output_folder`) and check that a
    file can be made in it, so that a read-only place fails at once, before any work, with an
    ``OSError`` naming it."""
    path = check_output_folder(path, option=option)
    path.mkdir(parents=True, exist_ok=True)
    probe_writable(path, f".clonedrive-write-test-{os.getpid()}")
    return path


#: OS errors that say where a file could not be written or read -- the disk, the folder, its
#: permissions -- rather than that the program is wrong; :func:`describe_os_error` names them.
FILE_SYSTEM_ERRNOS = {
    errno.ENOSPC: "no space left on the device (disk full)",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file too large (a file-size limit was reached)",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied (a read-only folder?)",
    errno.EPERM: "operation not permitted",
    errno.ENAMETOOLONG: "file name too long",
    errno.EISDIR: "is a folder, expected a file",
    errno.ENOTDIR: "a part of the path is a file, not a folder",
    errno.EEXIST: "already exists",
    errno.ENOENT: "no such file or folder",
    errno.EIO: "input/output error (a failing disk?)",
    errno.ELOOP: "a symbolic link where an output belongs, or a loop of links",
}


def describe_os_error(error: OSError) -> str:
    """One line naming the path and what went wrong, for an error of
    :data:`FILE_SYSTEM_ERRNOS` (others, and errors raised with a reason of their own: the
    error's own text)."""
    reason = FILE_SYSTEM_ERRNOS.get(error.errno) or error.strerror or str(error)
    if error.errno is not None and error.strerror and error.strerror != os.strerror(error.errno):
        reason = error.strerror  # a reason written for this error: the need, what is free
    path = error.filename if error.filename is not None else None
    return f"{os.fsdecode(path)}: {reason}" if path is not None else reason


def with_filename(error: OSError, path: str | os.PathLike) -> OSError:
    """``error`` if it names its file, else the same error (same type and errno) naming
    ``path``: ``os.write`` and ``fsync`` errors say only "No space left on device"."""
    if error.filename is not None or error.errno is None:
        return error
    named = OSError(error.errno, error.strerror, os.fspath(path))
    named.__cause__ = error
    return named
