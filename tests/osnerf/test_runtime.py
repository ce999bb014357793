"""tune_malloc applies glibc's settings where there is glibc and can be switched off."""

import platform

import pytest

from osnerf import tune_malloc


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's")
def test_tune_malloc_applies_on_glibc_and_is_off_by_environment(monkeypatch):
    assert tune_malloc() is True
    monkeypatch.setenv("OSNERF_MALLOC_TUNE", "0")
    assert tune_malloc() is False
