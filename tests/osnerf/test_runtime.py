"""tune_malloc applies glibc's settings where there is glibc and can be switched off."""

import platform

import pytest

from osnerf import tune_malloc


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's")
def test_tune_malloc_applies_on_glibc_and_is_off_by_environment(monkeypatch):
    assert tune_malloc() is True
    monkeypatch.setenv("OSNERF_MALLOC_TUNE", "0")
    assert tune_malloc() is False


def test_a_command_reads_the_commit_before_it_runs(monkeypatch, capsys):
    """A long run writes its result at the end; the commit it names is read when it starts
    (the code it loaded), not when the checkout may already hold the next commit."""
    import importlib

    from osnerf import git_commit
    from osnerf.cli import main

    module = importlib.import_module("osnerf.commands.scenes")
    real = module.run
    cached_at_start = []

    def run(args):
        cached_at_start.append(git_commit.cache_info().currsize)
        return real(args)

    git_commit.cache_clear()
    monkeypatch.setattr(module, "run", run)
    assert main(["scenes"]) == 0
    assert cached_at_start == [1]
