"""serve maps large blocks on their own (glibc): a stream's growing arrays go back to the system when freed instead of
staying fragmented in the heap, where glibc's rising mmap threshold put them (+65-84 MB after four 300 s streams)."""

from __future__ import annotations

import subprocess
import sys

import pytest

# In a fresh process: free a 16 MB block (glibc then raises its mmap threshold to 16 MB; never past 32 MB), allocate
# 1 MB and report whether it got its own mapping (mallinfo2's hblkhd grows by it). argv[1] = "1": map_large_blocks()
# first.
PROBE = """
import ctypes, sys
import numpy as np
from robogest.live.serve_limits import map_large_blocks

class MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                "fsmblks", "uordblks", "fordblks", "keepcost")]
libc = ctypes.CDLL(None)
libc.mallinfo2.restype = MallInfo2
if sys.argv[1] == "1":
    map_large_blocks()
big = np.ones(16 * 1024 * 1024, np.uint8)
del big
before = libc.mallinfo2().hblkhd
block = np.ones(1024 * 1024, np.uint8)
print(int(libc.mallinfo2().hblkhd - before >= 1024 * 1024))
"""


def _mapped(call: bool) -> bool:
    r = subprocess.run([sys.executable, "-c", PROBE, "1" if call else "0"], capture_output=True, text=True)
    if r.returncode:
        pytest.skip(f"no glibc mallinfo2 here: {r.stderr.strip().splitlines()[-1:]}")
    return r.stdout.strip() == "1"


def test_large_blocks_get_their_own_mapping_after_a_larger_one_was_freed():
    assert not _mapped(False), "glibc's default: after a 16 MB block is freed, a 1 MB block comes from the heap"
    assert _mapped(True)
