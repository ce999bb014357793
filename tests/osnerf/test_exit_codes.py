"""Exit codes: 2 for bad input (before a command has checked its inputs), 1 for a failure after."""

import pytest

import osnerf.commands.ber as ber
from osnerf.cli import main

ARGV = ["ber", "--channel", "awgn", "--snr-db", "0", "--num-bits", "1000"]


def _boom(*_args, **_kwargs):
    raise ValueError("a numerical failure deep inside")


def test_bad_input_exits_2_and_names_the_flag(tmp_path, capsys):
    assert main([*ARGV[:-1], "-5", "--out", str(tmp_path / "b.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--num-bits" in err[0] and "error:" in err[0]


@pytest.mark.parametrize("exc", [ValueError, KeyError, FileNotFoundError])
def test_a_failure_after_the_inputs_are_checked_exits_1(tmp_path, capsys, monkeypatch, exc):
    def boom(*_args, **_kwargs):
        raise exc("a failure deep inside the work")

    monkeypatch.setattr(ber, "simulate", boom)
    assert main([*ARGV, "--out", str(tmp_path / "b.json")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"failed: {exc.__name__}: a failure deep inside" in err[0]
    assert not (tmp_path / "b.json").exists()


def test_the_same_error_while_reading_inputs_is_bad_input(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(ber, "parse_args", _boom)
    assert main([*ARGV, "--out", str(tmp_path / "b.json")]) == 2
    assert "error: a numerical failure deep inside" in capsys.readouterr().err


def test_input_found_bad_during_the_work_is_still_bad_input(tmp_path, capsys, monkeypatch):
    """Some input can only be found unservable on the way (no camera sees the demand): a
    ``common.InputError`` exits 2 after the inputs were checked too."""
    from common import InputError

    def unservable(*_args, **_kwargs):
        raise InputError("no drone camera sees the demanded object(s) post")

    monkeypatch.setattr(ber, "simulate", unservable)
    assert main([*ARGV, "--out", str(tmp_path / "b.json")]) == 2
    assert "error: no drone camera sees" in capsys.readouterr().err
