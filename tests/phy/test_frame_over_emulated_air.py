"""The frame receiver against an independent impairment model: hil's emulated HackRF pair
(int8 ADC/DAC, fractional delay, crystal ppm -> CFO and sampling-clock drift, multipath,
DC offset, I/Q imbalance)."""

import math

import numpy as np
import pytest
import torch

import phy

hil = pytest.importorskip("hil")

FS = 4e6
FC = 2.4e9


def _qpsk(n, seed=0):
    b = np.random.default_rng(seed).integers(0, 2, size=(n, 2))
    return (((1 - 2 * b[:, 0]) + 1j * (1 - 2 * b[:, 1])) / math.sqrt(2)).astype(np.complex64)


@pytest.mark.parametrize(
    "snr_db, ppm, multipath, max_ser",
    [
        (30.0, (0.0, 20.0), (), 0.0),
        (20.0, (0.0, -25.0), ((3, 0.5j), (7, -0.25)), 0.01),
    ],
)
def test_frame_through_emulated_radios(snr_db, ppm, multipath, max_ser):
    cfg = phy.FrameConfig(sample_rate_hz=FS)
    x = _qpsk(3000)
    sig = np.r_[np.zeros(2000, np.complex64), phy.build_frame(x, cfg), np.zeros(2000, np.complex64)]
    air = hil.AirChannel(
        snr_db=snr_db,
        reference_power_dbfs=20 * math.log10(cfg.rms_amplitude),
        delay_s=123.4 / FS,
        multipath=multipath,
        dc_offset=0.02 + 0.01j,
        iq_gain_imbalance_db=0.5,
        iq_phase_imbalance_deg=3.0,
    )
    tx, rx, _ = hil.loopback_pair(air, ppm=ppm, seed=1, rx_chunk_bytes=16384)
    with tx, rx:
        for radio in (tx, rx):
            radio.sample_rate_hz = FS
            radio.center_freq_hz = FC
        rx.lna_gain_db, rx.vga_gain_db = 16, 24
        tx.tx(sig)
        y = rx.rx(len(sig) + 1000)[0]
    res = phy.receive_frame(y, cfg, 3000)
    assert res.detected and abs(res.start_index - 2123) <= 1
    cfo_true_hz = FC * (ppm[0] - ppm[1]) * 1e-6
    assert abs(res.cfo_hz - cfo_true_hz) < 0.01 * cfg.subcarrier_spacing_hz
    assert abs(res.sco_ppm - (ppm[1] - ppm[0])) < 5
    ser = (
        (phy.hard_decision(res.symbols, "qpsk") != phy.hard_decision(torch.from_numpy(x), "qpsk"))
        .float()
        .mean()
    )
    assert ser <= max_ser
    err = np.abs(res.symbols.numpy() - x) ** 2
    assert err.mean() == pytest.approx(res.noise_var.mean().item(), rel=0.35)
    # thermal SNR per used carrier = snr_db + 10 log10(64 / 52); the I/Q image (about
    # -28 dB here) and the residual DC rotate differently in the two training symbols once
    # the CFO is removed, so they reach the training-difference estimate too (-1.6 dB at
    # 30 dB); the effective SNR (every pilot's residual) is below it, up to the training
    # estimate's own spread (52 carriers: +-0.6 dB)
    assert res.snr_db_estimate == pytest.approx(snr_db + 10 * math.log10(64 / 52), abs=2.0)
    assert res.effective_snr_db < res.snr_db_estimate + 1.0
