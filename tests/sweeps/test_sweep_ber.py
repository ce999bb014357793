"""The issue's own example: a `ber` sweep (modulation x SNR), resumed, plotted, against theory."""

from __future__ import annotations

import importlib.util
import json
import math

import pytest

import osnerf.cli
from osnerf.sweeps import read_results

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("osnerf.commands.ber") is None,
    reason="`osnerf ber` is not in this checkout",
)

SPEC = """\
command: ber
fixed: {channel: awgn, num_bits: 40000}
axes: {modulation: [qpsk, 16qam], snr_db: [0, 6]}
seeds: [0]
"""


def test_ber_sweep_matches_the_command_run_alone_and_theory(tmp_path, capsys):
    spec = tmp_path / "ber.yaml"
    spec.write_text(SPEC)
    out = tmp_path / "ber.jsonl"
    argv = ["sweep", str(spec), "--out", str(out), "--executor", "serial", "--no-progress"]
    assert osnerf.cli.main(argv) == 0
    records = read_results(out)
    assert sorted((r["point"]["modulation"], r["point"]["snr_db"]) for r in records) == [
        ("16qam", 0),
        ("16qam", 6),
        ("qpsk", 0),
        ("qpsk", 6),
    ]
    for r in records:
        m = r["metrics"]
        assert m["snr_db"] == r["point"]["snr_db"] and m["num_bits"] >= 40000
        sigma = math.sqrt(m["ber_theory"] * (1 - m["ber_theory"]) / m["num_bits"])
        assert abs(m["ber"] - m["ber_theory"]) < 4 * sigma  # Monte Carlo vs closed form
    # one point run alone gives the same numbers: the sweep runs the same command line
    one = next(r for r in records if r["point"] == {"modulation": "16qam", "snr_db": 6})
    alone = tmp_path / "alone.json"
    assert osnerf.cli.main(["ber", *one["argv"], "--out", str(alone)]) == 0
    entry = json.loads(alone.read_text())["results"][0]
    assert (entry["ber"], entry["num_errors"]) == (
        one["metrics"]["ber"],
        one["metrics"]["num_errors"],
    )
    # re-running is a no-op
    capsys.readouterr()
    assert osnerf.cli.main(argv) == 0
    assert "4 already done, 0 finished now" in capsys.readouterr().err
    assert len(read_results(out)) == 4
    assert osnerf.cli.main(["plot", str(out), "--out", str(tmp_path / "figs")]) == 0
    assert (tmp_path / "figs" / "ber_vs_snr.pdf").stat().st_size > 5000
