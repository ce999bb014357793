"""trim_heap gives the heap's free pages back: a fragmented heap shrinks in resident size."""

import sys

import pytest

from common import trim_heap


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc and /proc only")
def test_trim_heap_releases_freed_blocks_between_live_ones():
    # 64 kB blocks come from the heap (below glibc's mmap threshold); keeping every 16th
    # alive stops free() from shrinking the heap at its top, so only a trim releases them
    blocks = [bytearray(64 << 10) for _ in range(4096)]  # 256 MB, touched (zero-filled)
    kept = blocks[::16]
    del blocks
    before = _rss_mb()
    assert trim_heap()
    after = _rss_mb()
    assert before - after > 150, (before, after)
    assert len(kept) == 256
