"""Keep freed memory in the process for the next allocation (glibc's malloc).

Training allocates and frees arrays of tens of MB on every batch: a batch of images as floats,
its augmented copy, the network's activations and their gradients. glibc's malloc serves
blocks that large with fresh pages from ``mmap`` and hands them back with ``munmap`` on free,
so every batch faults its memory in again, page by page, in the kernel.
:func:`keep_freed_memory` tells malloc to serve them from its heap instead and to keep what is
freed there for the next batch. The arithmetic, and so every result, is unchanged; only the
kernel's work goes. ``docs/results/`` has the measurement.

Called by the command line's entry point and by each worker process, never at import.
"""

from __future__ import annotations

import ctypes
import sys

#: mallopt's parameter numbers (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_TOP_PAD = -2
M_MMAP_MAX = -4
#: Free memory at the heap's top kept rather than returned to the system [bytes] (C int's max).
KEEP_BYTES = 2**31 - 1
#: Extra memory taken each time the heap grows, so a growing batch does not grow it each time.
TOP_PAD_BYTES = 256 << 20


def keep_freed_memory() -> bool:
    """Serve every allocation from malloc's heap (no ``mmap`` per large block) and keep freed
    memory there. True when the C library took the settings; False where it has no
    ``mallopt`` (not Linux, or not glibc), which changes nothing else."""
    if not sys.platform.startswith("linux"):
        return False
    mallopt = getattr(ctypes.CDLL(None), "mallopt", None)
    if mallopt is None:
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    settings = ((M_MMAP_MAX, 0), (M_TRIM_THRESHOLD, KEEP_BYTES), (M_TOP_PAD, TOP_PAD_BYTES))
    return all(mallopt(parameter, value) == 1 for parameter, value in settings)
