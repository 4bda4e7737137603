"""Progress bars for long work: redrawn twice a second on a terminal, every 30 s into a log."""

from __future__ import annotations

import sys


def progress_bar(iterable=None, *, total=None, desc: str = "", unit: str = "it",
                 enabled: bool = True, **kwargs):
    """A ``tqdm`` bar on stderr that does not flood logs when stderr is not a terminal."""
    from tqdm import tqdm

    interactive = sys.stderr.isatty()
    kwargs.setdefault("mininterval", 0.5 if interactive else 30.0)
    kwargs.setdefault("dynamic_ncols", True)
    return tqdm(iterable, total=total, desc=desc, unit=unit, disable=not enabled, **kwargs)
