"""Link helpers of the pipeline: MRC of repeated blocks, the per-position (ray-traced) channel."""

import numpy as np
import pytest
import torch

import phy
from osnerf.scu import combined_snr_db
from phy import combine_repetitions
from phy.raytrace import PerPositionChannel


def test_mrc_of_two_zf_copies_adds_their_snrs():
    """Block Rayleigh, ZF with perfect CSI: copy r has noise variance s / |h_r|^2; after MRC
    the variance is 1 / sum(1 / nv_r) = s / (|h_1|^2 + |h_2|^2), and the error matches it."""
    gen = torch.Generator().manual_seed(0)
    link = phy.FlatLink(phy.make_channel("rayleigh"), csi="perfect", equalizer="zf")
    n = 200_000
    x = phy.power_normalize(torch.randn(1, n, dtype=torch.complex64, generator=gen))
    out = link(x.expand(2, -1).contiguous(), 0.0, generator=gen)
    xc, nv = combine_repetitions(out.x_hat, out.noise_var)
    expected = 1.0 / (1.0 / out.noise_var[:, 0]).sum()
    assert float(nv[0, 0]) == pytest.approx(float(expected), rel=1e-5)
    assert float((xc - x).abs().pow(2).mean()) == pytest.approx(float(expected), rel=0.02)
    assert float(nv[0, 0]) <= float(out.noise_var[:, 0].min())  # never worse than the best copy


def test_codec_is_told_the_average_snr_after_combining_the_copies():
    """MRC of r block-faded copies adds their SNRs, so its mean is r times one copy's: the
    SNR the SCU tells the codec is measured + 10 log10(r), clamped to the codec's range."""
    gen = torch.Generator().manual_seed(2)
    link = phy.FlatLink(phy.make_channel("rayleigh"), csi="perfect", equalizer="zf")
    x = phy.power_normalize(torch.randn(1, 4, dtype=torch.complex64, generator=gen))
    snr = []
    for _ in range(4000):
        out = link(x.expand(2, -1).contiguous(), 3.0, generator=gen)
        snr.append(float(1.0 / combine_repetitions(out.x_hat, out.noise_var)[1][0, 0]))
    mean_db = 10 * np.log10(np.mean(snr))
    assert mean_db == pytest.approx(combined_snr_db(3.0, 2, (-10.0, 20.0)), abs=0.15)
    assert combined_snr_db(3.0, 2, (-10.0, 20.0)) == pytest.approx(3.0 + 10 * np.log10(2))
    assert combined_snr_db(3.0, 1, (-10.0, 20.0)) == 3.0
    assert combined_snr_db(19.0, 2, (-10.0, 20.0)) == 20.0  # clamped


def test_per_position_channel_is_normalised_and_frequency_selective():
    h = np.array([2.0, 0.5j, -1.0, 0.1 + 0.1j], np.complex64)
    ch = PerPositionChannel(h)
    assert float((ch.h.abs() ** 2).mean()) == pytest.approx(1.0, rel=1e-6)
    gen = torch.Generator().manual_seed(1)
    n = 40_000
    x = phy.power_normalize(torch.randn(2, n, dtype=torch.complex64, generator=gen))
    out = ch(x, 10.0, generator=gen)
    hk = ch.h[torch.arange(n) % 4]
    noise = out.y - hk * x
    assert float(noise.abs().pow(2).mean()) == pytest.approx(0.1, rel=0.03)
    torch.testing.assert_close(out.h[0], hk)
    link = phy.FlatLink(ch, csi="perfect", equalizer="zf")
    lo = link(x, 10.0, generator=gen)
    # ZF noise on subcarrier k is 0.1 / |h_k|^2
    expected = 0.1 / (hk.abs() ** 2)
    torch.testing.assert_close(lo.noise_var[0], expected.float(), rtol=1e-4, atol=1e-6)
