"""The over-the-air link of `osnerf run --channel ota`: symbols through two emulated
HackRFs (USB protocol, OFDM frames, int8 air) behave like a link, burst after burst."""

import json

import pytest
import torch

from hil import OtaConfig
from osnerf.cli import main
from osnerf.ota_link import OtaLink, open_radios


def _qpsk(gen, batch, n):
    b = torch.randint(0, 2, (batch, n, 2), generator=gen)
    return ((1 - 2 * b[..., 0]) + 1j * (1 - 2 * b[..., 1])).to(torch.complex64) / 2**0.5


def test_every_burst_arrives_and_the_reported_noise_matches_the_errors():
    cfg = OtaConfig()
    tx, rx, emu = open_radios("emulated", 15.0, cfg, seed=3)
    link = OtaLink(tx, rx, 15.0, cfg, emu)
    gen = torch.Generator().manual_seed(0)
    try:
        for batch, n in [(2, 3000), (1, 256), (3, 1000)]:  # several bursts on one air
            x = _qpsk(gen, batch, n)
            out = link(x, 15.0)
            assert out.x_hat.shape == x.shape and out.noise_var.shape == x.shape
            mse = (out.x_hat - x).abs().pow(2).mean().item()
            nv = out.noise_var.mean().item()
            # 15 dB air: residual error near 10^-1.5, and the receiver's own estimate agrees
            assert 0.005 < mse < 0.1, mse
            assert 0.5 < nv / mse < 2.0, (nv, mse)
        assert link.frames_lost == 0
        assert link.frames_sent == 2 * 2 + 1 + 3  # 3000 symbols need two 2048-symbol frames
        with pytest.raises(ValueError, match="runs at 15 dB, asked for 3 dB"):
            link(x, 3.0)
    finally:
        link.close()


def test_run_over_the_air_reports_the_frames(tmp_path):
    out = tmp_path / "ota"
    rc = main(
        ["run", "--scene", "tiny", "--channel", "ota", "--snr-db", "15", "--schemes", "jscc"]
        + ["--resolution", "32", "--views", "4", "--test-views", "2", "--max-seconds", "2"]
        + ["--renderer-steps", "0"]
        + ["--cache-dir", str(tmp_path / "cache"), "--out", str(out)]
    )
    assert rc == 0
    report = json.loads((out / "report.json").read_text())
    link = report["link"]
    assert link["channel"] == "ota" and link["device"] == "emulated"
    assert link["frames_sent"] >= 4 and link["frames_lost"] == 0
    assert link["air_snr_db"] == 15.0 and abs(link["snr_db_measured"] - 15.0) < 1.5
    assert report["schemes"]["jscc"]["psnr_received"] > 15.0
