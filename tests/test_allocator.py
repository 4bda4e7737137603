"""keep_freed_memory: a large block freed and allocated again reuses the same pages.

Each case runs in a fresh interpreter, since the setting stays for the process's life.
"""

import subprocess
import sys

import pytest

_ALLOCATE = """
import ctypes, resource, sys
from clonedrive.base.allocator import keep_freed_memory
took = keep_freed_memory() if sys.argv[1] == "keep" else None
libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
size = 128 * 86 * 320 * 3 * 4  # 42 MB: a training batch's floats
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    block = libc.malloc(size)
    ctypes.memset(block, 1, size)
    libc.free(block)
print(took, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _page_faults(mode: str) -> tuple[str, int]:
    result = subprocess.run([sys.executable, "-c", _ALLOCATE, mode], capture_output=True,
                            text=True, timeout=60, check=True)
    took, faults = result.stdout.split()
    return took, int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_freed_blocks_are_reused_instead_of_faulted_in_again():
    took, kept = _page_faults("keep")
    _, default = _page_faults("default")
    assert took == "True"
    # By default a block above 32 MB is always fresh mmap'd memory: 10,320 page faults each time.
    assert default > 20 * 10_000
    assert kept < default / 10
