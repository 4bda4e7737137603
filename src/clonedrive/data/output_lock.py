"""One writer per output, and no output over an input: :func:`claim_output`.

Two ``evaluate`` runs into one ``--out`` both exit 0 and one's results are lost; two ``train``
runs interleave their checkpoints; ``ensemble a.keras b.keras --out a.keras`` replaces a member
while reading it. Every command that writes a run folder or a model file holds this lock while
it writes. It is the recorder's lock (:class:`~clonedrive.data.recording_lock.RecordingLock`:
``flock`` on a small JSON file naming the writer's PID, taken over with a warning when its
process died), in the output folder (:data:`FOLDER_LOCK_NAME`) or, for one output file, beside
it (``.<file name>`` + :data:`FILE_LOCK_SUFFIX`).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from clonedrive.data.recording_lock import RecordingLock

FOLDER_LOCK_NAME = ".clonedrive-writer.lock"
FILE_LOCK_SUFFIX = ".clonedrive-writer.lock"


def check_output_over_inputs(out: str | os.PathLike, inputs: Iterable[str | os.PathLike], *,
                             option: str = "--out") -> None:
    """``ValueError`` if ``out`` is one of ``inputs`` or inside one (links resolved), naming
    both: a run must never write over, or into, what it reads."""
    target = Path(out).resolve()
    for given in inputs:
        source = Path(given).resolve()
        if target == source:
            raise ValueError(f"{option} {out} is the input {given}; write somewhere else")
        if source in target.parents:
            raise ValueError(f"{option} {out} is inside the input {given}; write somewhere else")


def claim_output(verb: str, out: str | os.PathLike, *,
                 inputs: Iterable[str | os.PathLike] = (), is_file: bool = False,
                 option: str = "--out") -> RecordingLock:
    """The lock on ``out`` (a folder, or with ``is_file`` one file) for ``clonedrive VERB``,
    acquired, after checking that ``out`` is none of ``inputs`` nor inside one; a ``with``
    block on it releases it at the end.

    Raises ``ValueError`` for an output over an input and
    :class:`~clonedrive.data.recording_lock.RecordingLockedError` (a ``ValueError`` too),
    naming the other writer's PID, when a live process holds it.
    """
    out = Path(out)
    check_output_over_inputs(out, inputs, option=option)
    if is_file:
        lock = RecordingLock(out.parent, name=f".{out.name}{FILE_LOCK_SUFFIX}",
                             writer=f"clonedrive {verb}", target=out)
    else:
        lock = RecordingLock(out, name=FOLDER_LOCK_NAME, writer=f"clonedrive {verb}")
    return lock.acquire()
