"""Every writing verb's first step: claim its output (:func:`claim`)."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable

from clonedrive.data.recording_lock import RecordingLock


def claim(verb: str, out: str | os.PathLike, *, inputs: Iterable[str | os.PathLike] = (),
          is_file: bool = False) -> RecordingLock | None:
    """The held lock on ``out`` for ``clonedrive VERB``
    (:func:`clonedrive.data.output_lock.claim_output`), or None after printing why not (the
    output is one of ``inputs`` or inside one, another process writes it): exit 1."""
    from clonedrive.data.output_lock import claim_output

    try:
        return claim_output(verb, out, inputs=inputs, is_file=is_file)
    except ValueError as error:
        print(f"clonedrive {verb}: {error}", file=sys.stderr)
        return None
