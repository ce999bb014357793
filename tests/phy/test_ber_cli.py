"""`osnerf ber`: the JSON contract, the plot, and one-line errors with exit code 2."""

import json

import pytest

from osnerf.cli import main


def test_ber_writes_the_contracted_json_and_plot(tmp_path):
    out, png = tmp_path / "ber.json", tmp_path / "ber.png"
    rc = main(
        [
            "ber",
            "--channel",
            "awgn",
            "--modulation",
            "qpsk",
            "--snr-db",
            "0,6",
            "--num-bits",
            "200000",
            "--seed",
            "0",
            "--out",
            str(out),
            "--plot",
            str(png),
        ]
    )
    assert rc == 0
    d = json.loads(out.read_text())
    assert d["seed"] == 0 and d["git_commit"] and d["config"]["channel"] == "awgn"
    assert [r["snr_db"] for r in d["results"]] == [0.0, 6.0]
    for r in d["results"]:
        assert {"snr_db", "ber", "ber_theory", "num_bits", "num_errors"} <= set(r)
        assert r["num_bits"] == 200_000 and r["ber"] == r["num_errors"] / r["num_bits"]
        sigma = (r["ber_theory"] * (1 - r["ber_theory"]) / r["num_bits"]) ** 0.5
        assert abs(r["ber"] - r["ber_theory"]) < 4 * sigma
    assert png.stat().st_size > 1000 and png.read_bytes()[:4] == b"\x89PNG"


def test_negative_snr_lists_parse(tmp_path):
    out = tmp_path / "neg.json"
    assert main(["ber", "--snr-db", "-10,-2.5", "--num-bits", "2000", "--out", str(out)]) == 0
    assert [r["snr_db"] for r in json.loads(out.read_text())["results"]] == [-10.0, -2.5]


def test_same_seed_same_result(tmp_path):
    args = [
        "ber",
        "--channel",
        "rayleigh",
        "--modulation",
        "16qam",
        "--snr-db",
        "10",
        "--num-bits",
        "20000",
        "--seed",
        "3",
    ]
    assert main([*args, "--out", str(tmp_path / "a.json")]) == 0
    assert main([*args, "--out", str(tmp_path / "b.json")]) == 0
    a = json.loads((tmp_path / "a.json").read_text())["results"]
    b = json.loads((tmp_path / "b.json").read_text())["results"]
    assert a[0]["num_errors"] == b[0]["num_errors"]


@pytest.mark.parametrize(
    "flag, value, match",
    [
        (
            "--channel",
            "rician",
            "--channel: invalid choice: 'rician' (choose from 'awgn', 'rayleigh')",
        ),
        (
            "--modulation",
            "8psk",
            "--modulation: invalid choice: '8psk' (choose from 'bpsk', 'qpsk', '16qam', '64qam')",
        ),
        ("--snr-db", "0,100", "--snr-db: must be comma-separated numbers in [-30, 60] dB"),
        ("--snr-db", "zero", "--snr-db: must be comma-separated numbers"),
        ("--snr-db", "0,,5", "--snr-db: must be comma-separated numbers"),
        ("--seed", "-1", "--seed: must be an integer in [0, "),
        ("--seed", "1e23", "--seed: must be an integer in [0, "),
        ("--num-bits", "-5", "--num-bits must be in"),
        ("--num-bits", "1e3.5", "--num-bits must be an integer"),
        ("--plot", "x.pdf", "--plot must be a .png"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, flag, value, match):
    out = tmp_path / "ber.json"
    argv = ["ber", "--snr-db", "0", "--num-bits", "1000", "--out", str(out), flag, value]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert match in err and len(err.splitlines()) == 1
    assert not out.exists()
