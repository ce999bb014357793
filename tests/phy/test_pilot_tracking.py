"""Pilots against a moving drone: what LS with linear interpolation in time makes of a
Doppler-rotating channel (the sparse-pilot error floor, in closed form), and sionna's
LMMSE estimator beside it."""

import math

import numpy as np
import pytest
import torch

import phy
from phy.ofdm import LMMSEEstimator
from phy.raytrace import RayTracedChannel, RayTracer, RayTracingConfig, max_doppler_hz

pytestmark = pytest.mark.raytracing

FC = 2.4e9
GRID = phy.ResourceGrid()  # 15 kHz, pilots on OFDM symbols 2 and 11 of 14
T_SYM = GRID.symbol_length / GRID.sample_rate_hz


@pytest.fixture(scope="module")
def channel():
    """A drone 100 m away flying at 30 m/s straight at the station: one path whose phase
    turns by w = 2 pi f_d T_SYM per OFDM symbol."""
    import sionna.rt as srt

    tracer = RayTracer(srt.load_scene(), (0.0, 0.0, 0.0), FC, RayTracingConfig(max_depth=0))
    return RayTracedChannel(
        tracer=tracer,
        tx_positions_m=[[100.0, 0.0, 0.0]],
        tx_velocities_m_s=[-30.0, 0.0, 0.0],
        subcarrier_frequencies_hz=GRID.subcarrier_frequencies_hz,
        ofdm_symbol_duration_s=T_SYM,
    )


def _received(channel, snr_db: float, seed: int = 0):
    x = phy.map_to_grid(torch.zeros(1, GRID.num_data_symbols, dtype=torch.complex64), GRID)
    return channel(x, snr_db, generator=torch.Generator().manual_seed(seed))


def test_ls_interpolates_the_rotating_phasor_linearly(channel):
    """Between pilot symbols p0 = 2 and p1 = 11 the estimate at symbol l is the chord
    (1 - a) h(p0) + a h(p1), a = (l - p0) / 9, of magnitude
    sqrt((1-a)^2 + a^2 + 2 a (1-a) cos 9w); outside it holds the nearest pilot symbol,
    lagging by w per symbol. Hence the floor: the estimate shrinks and lags as v grows."""
    out = _received(channel, 60.0)
    h_hat, _ = phy.ls_channel_estimate(out.y, GRID, out.noise_var)
    used = GRID.used_subcarriers
    h = out.h[0][:, used]  # [num_ofdm_symbols, used] true response
    e = (h_hat[0][:, used] / h).mean(dim=1).numpy()  # estimate relative to the truth
    w = 2 * math.pi * max_doppler_hz(30.0, FC) * T_SYM
    for sym in range(14):
        if sym < 2 or sym > 11:
            p = 2 if sym < 2 else 11
            expected = np.exp(1j * w * (p - sym))
        else:
            a = (sym - 2) / 9
            expected = (1 - a) * np.exp(-1j * w * (sym - 2)) + a * np.exp(1j * w * (11 - sym))
        assert abs(e[sym] - expected) < 2e-3, sym
    assert abs(e[6]) < 0.9  # at 30 m/s the estimate mid-gap is 1.5 dB short


def test_lmmse_beats_ls_on_a_moving_drone(channel):
    """The same drone at 10 dB: LMMSE filtering (Jakes time covariance at the drone's speed)
    has a lower mean squared error than LS and a BER no worse."""
    lmmse = LMMSEEstimator(GRID, 30.0, FC, 100e-9)
    mse = {"ls": 0.0, "lmmse": 0.0}
    for seed in range(20):
        out = _received(channel, 10.0, seed)
        used = GRID.used_subcarriers
        for name, (h_hat, _) in {
            "ls": phy.ls_channel_estimate(out.y, GRID, out.noise_var),
            "lmmse": lmmse(out.y, out.noise_var),
        }.items():
            mse[name] += float((h_hat[0][:, used] - out.h[0][:, used]).abs().pow(2).mean())
    assert mse["lmmse"] < 0.5 * mse["ls"]
    ber = {}
    for csi in ("ls", "lmmse"):
        link = phy.OFDMLink(GRID, channel, csi=csi, equalizer="zf", estimator=lmmse)
        r = phy.simulate_uncoded("16qam", link, 12.0, 200_000, torch.Generator().manual_seed(1))
        ber[csi] = r.ber
    assert ber["lmmse"] <= ber["ls"]


def test_lmmse_needs_its_estimator():
    with pytest.raises(ValueError, match="csi='lmmse' needs estimator"):
        phy.OFDMLink(GRID, phy.make_channel("awgn"), csi="lmmse")
    with pytest.raises(ValueError, match="speed_m_s must be a finite number >= 0"):
        LMMSEEstimator(GRID, -1.0, FC)
    other = phy.ResourceGrid(pilot_ofdm_symbols=(0, 7))
    with pytest.raises(ValueError, match="estimator must be built for the link's grid"):
        phy.OFDMLink(
            GRID, phy.make_channel("awgn"), csi="lmmse", estimator=LMMSEEstimator(other, 0.0, FC)
        )
