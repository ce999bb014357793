"""A sweep's results file on a full disk keeps no torn line and names itself; a torn line
read by plot is said; --max-points counts the points that run; an edited spec is refused
saying what changed."""

from __future__ import annotations

import errno

import pytest
import sweep_fake_command as fake

import osnerf.cli
import osnerf.sweeps.store as store
from osnerf.sweeps import append_record, read_results, run_sweep, spec_from_dict


@pytest.fixture(autouse=True)
def fake_command(monkeypatch):
    from common import Registry

    table = Registry("command", {**osnerf.cli.COMMANDS, fake.NAME: fake.ENTRY})
    monkeypatch.setattr(osnerf.cli, "COMMANDS", table)


def test_a_full_disk_mid_line_leaves_no_torn_line_and_names_the_file(tmp_path, monkeypatch):
    out = tmp_path / "r.jsonl"
    append_record(out, {"point": {"a": 1}, "spec_hash": "x"})
    before = out.read_bytes()
    real = store._write

    def full(fd, data):
        real(fd, data[: len(data) // 2])  # half the line reaches the disk, then ENOSPC
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(store, "_write", full)
    with pytest.raises(OSError) as e:
        append_record(out, {"point": {"a": 2}, "spec_hash": "x"})
    assert e.value.filename == str(out) and e.value.errno == errno.ENOSPC
    assert out.read_bytes() == before  # the earlier point, and no half of the new one


def test_plot_says_when_it_leaves_a_torn_line_out(tmp_path, capsys):
    out = tmp_path / "r.jsonl"
    append_record(out, {"point": {"a": 1}, "spec_hash": "x"})
    with open(out, "ab") as f:
        f.write(b'{"point": {"a": 2}, "spec_h')
    assert len(read_results(out)) == 1
    err = capsys.readouterr().err
    assert str(out) in err and "partial last line" in err


def test_max_points_counts_the_points_that_run(tmp_path):
    d = {
        "command": "fake",
        "axes": {"snr_db": [0, 5, 10], "mode": ["a", "b"]},
        "seeds": [0],
        "exclude": [{"mode": "b"}],
    }
    assert spec_from_dict(d, max_points=3).num_points == 6  # 3 run, 3 left out
    with pytest.raises(ValueError, match="the spec has 3 points, more than --max-points 2"):
        spec_from_dict(d, max_points=2)


def test_an_edited_exclude_is_refused_saying_what_changed(tmp_path):
    out = tmp_path / "r.jsonl"
    base = {"command": "fake", "axes": {"snr_db": [0, 5]}, "seeds": [0]}
    run_sweep(spec_from_dict(base), out, executor="serial", progress=False)
    edited = spec_from_dict({**base, "exclude": [{"snr_db": 5}]})
    before = out.read_bytes()
    with pytest.raises(ValueError, match=r'exclude was null, is now \[\{"snr_db":5\}\]'):
        run_sweep(edited, out, executor="serial", progress=False)
    assert out.read_bytes() == before
