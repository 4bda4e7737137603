"""A real, tiny, full-able disk for the tests: a tmpfs of a few hundred KB mounted on a
folder (``mount -t tmpfs``, which needs root, as in this project's containers) and unmounted
after. Where mounting is not permitted the test is skipped, saying why."""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest


@contextmanager
def mounted_tmpfs(folder: Path, size: str) -> Iterator[Path]:
    """``folder`` with a tmpfs of ``size`` (``mount``'s syntax: ``1m``, ``256k``) on it."""
    folder.mkdir(parents=True, exist_ok=True)
    if shutil.which("mount") is None:
        pytest.skip("no mount command: a tiny tmpfs cannot be made here")
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs",
                              str(folder)], capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.skip(f"mounting a tmpfs is not permitted here: {mounted.stderr.strip()}")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "--lazy", str(folder)], check=True)


def fill(disk: Path, leave_bytes: int) -> Path:
    """Fill ``disk`` with one file until ``leave_bytes`` (or less) are free; the file."""
    filler = disk / "filler"
    filler.write_bytes(bytes(max(0, shutil.disk_usage(disk).free - leave_bytes)))
    return filler
