"""Pilot measurements of a link: its SNR, and whether two copies of a block fade
independently (``phy.measure``)."""

import numpy as np
import pytest
import torch

import phy
from phy import measure_copy_fading, measure_snr_db

MIN_SPREAD_DB, MAX_CORRELATION = 1.0, 0.5  # the SCU's default thresholds


class StaticMultipathLink:
    """A static 3-tap channel seen through OFDM: symbol k sits on subcarrier k mod 64, whose
    gain |H_k|^2 is the same in every block; the receiver's noise variance carries a 10 %
    estimation error, drawn per block."""

    def __init__(self):
        h = np.fft.fft(np.array([1.0, 0, 0.4, 0, 0, 0.2j]), 64)
        self.gain = torch.from_numpy(np.abs(h) ** 2 / np.mean(np.abs(h) ** 2)).float()

    def __call__(self, x, snr_db, generator=None):
        g = self.gain.repeat(x.shape[-1] // 64 + 1)[: x.shape[-1]].expand(x.shape[0], -1)
        nv = 10 ** (-snr_db / 10) / g
        nv = nv * (1 + 0.1 * torch.randn(x.shape, generator=generator)).clamp_min(0.5)
        noise = torch.complex(*torch.randn((2, *x.shape), generator=generator)) * (nv / 2).sqrt()
        return phy.LinkOutput(x + noise, nv.float())


def test_copy_fading_tells_independent_fades_from_a_static_channel():
    """Pilot copies: AWGN has no fades (spread 0); block Rayleigh fades each copy on its own
    (the dB spread of an exponential |h|^2 is 10/ln10 * pi/sqrt(6) = 5.57 dB, a little less
    about each view's mean of 8 blocks; the copies uncorrelated); a static multipath channel
    fades its subcarriers by the same amount in both copies."""
    gen = torch.Generator().manual_seed(3)
    awgn = measure_copy_fading([phy.FlatLink(phy.make_channel("awgn"))] * 4, [0.0] * 4, gen)
    assert awgn.spread_db == pytest.approx(0.0, abs=1e-6) and not awgn.independent(
        MIN_SPREAD_DB, MAX_CORRELATION
    )
    block = phy.FlatLink(phy.make_channel("rayleigh"), csi="perfect", equalizer="zf")
    ray = measure_copy_fading([block] * 24, [0.0] * 24, gen)
    assert 4.0 < ray.spread_db < 6.5 and abs(ray.correlation) < 0.35
    assert ray.independent(MIN_SPREAD_DB, MAX_CORRELATION)
    static = measure_copy_fading([StaticMultipathLink()] * 4, [0.0] * 4, gen)
    assert static.spread_db > 1.5 and static.correlation > 0.9
    assert not static.independent(MIN_SPREAD_DB, MAX_CORRELATION)


@pytest.mark.parametrize("snr_db", [0.0, 10.0])
def test_measured_snr_matches_the_awgn_link(snr_db):
    link = phy.FlatLink(phy.make_channel("awgn"))
    gen = torch.Generator().manual_seed(1)
    est = measure_snr_db([link], [snr_db], gen, num_pilots=4096, num_blocks=4)[0]
    assert est == pytest.approx(snr_db, abs=0.15)  # 16k samples: std of the estimate ~0.05 dB


def test_measured_snr_of_rayleigh_mmse_is_the_mean_post_equalisation_snr():
    """Perfect-CSI MMSE on block Rayleigh: per block the unbiased SNR is |h|^2 / noise_var,
    so the average over many blocks is E|h|^2 / noise_var = the link SNR."""
    link = phy.FlatLink(phy.make_channel("rayleigh"), csi="perfect", equalizer="mmse")
    gen = torch.Generator().manual_seed(2)
    est = measure_snr_db([link], [5.0], gen, num_pilots=1024, num_blocks=2000)[0]
    assert est == pytest.approx(5.0, abs=0.3)
