"""glibc's heap: tune_malloc applies its settings (and can be switched off); trim_heap gives
the free pages back, so a fragmented heap shrinks in resident size."""

import platform
import sys

import pytest

from common import trim_heap, tune_malloc


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


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's")
def test_tune_malloc_applies_on_glibc_and_is_off_by_environment(monkeypatch):
    assert tune_malloc() is True
    monkeypatch.setenv("OSNERF_MALLOC_TUNE", "0")
    assert tune_malloc() is False
