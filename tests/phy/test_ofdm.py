"""OFDM identities, the resource grid, LS estimation statistics and OFDMLink."""

import math

import numpy as np
import pytest
import torch

import phy
from phy.channels.multipath import apply_taps, taps_frequency_response

G = torch.Generator


def _cn(shape, seed):
    z = torch.randn(*shape, 2, generator=G().manual_seed(seed)) * 0.5**0.5
    return torch.view_as_complex(z)


def test_default_grid_counts_by_hand():
    g = phy.ResourceGrid()
    # 64 carriers - 6 - 5 guards - DC = 52 used; 14 symbols, 2 of them pilots
    assert g.used_subcarriers.size == 52 and g.fft_size // 2 not in g.used_subcarriers
    assert g.num_data_symbols == 12 * 52
    assert int(g.pilot_mask.sum()) == 2 * 52 and g.num_samples == 14 * 80
    assert not (g.pilot_mask & g.data_mask).any()
    assert g.pilots.abs().allclose(torch.ones(104))
    comb = phy.ResourceGrid(pilot_ofdm_symbols=tuple(range(14)), pilot_subcarrier_spacing=4)
    # every 4th used carrier plus the last one: 0,4,...,48 and 51 -> 14 per symbol
    assert (
        comb.pilot_subcarriers.size == 14
        and comb.pilot_subcarriers[-1] == comb.used_subcarriers[-1]
    )


def test_modulate_demodulate_identity_and_energy():
    g = phy.ResourceGrid()
    x = _cn((3, g.num_ofdm_symbols, g.fft_size), 0)
    t = phy.ofdm_modulate(x, g.cp_length)
    assert t.shape == (3, g.num_samples)
    torch.testing.assert_close(
        phy.ofdm_demodulate(t, g.fft_size, g.cp_length), x, atol=1e-5, rtol=0
    )
    # orthonormal FFT: energy without the prefix equals the grid's energy
    body = t.reshape(3, g.num_ofdm_symbols, -1)[..., g.cp_length :]
    assert body.abs().pow(2).sum().item() == pytest.approx(x.abs().pow(2).sum().item(), rel=1e-5)


def test_cyclic_prefix_is_the_symbol_tail():
    g = phy.ResourceGrid(cp_length=12)
    t = phy.ofdm_modulate(_cn((2, 5, 64), 1), 12).reshape(2, 5, 76)
    torch.testing.assert_close(t[..., :12], t[..., -12:], atol=0, rtol=0)
    assert g.symbol_length == 76


@pytest.mark.parametrize("cp_offset", [0, 7, 16])
def test_early_fft_window_inside_the_prefix_is_compensated(cp_offset):
    x = _cn((1, 4, 64), 2)
    t = phy.ofdm_modulate(x, 16)
    torch.testing.assert_close(
        phy.ofdm_demodulate(t, 64, 16, cp_offset=cp_offset), x, atol=1e-4, rtol=0
    )


def test_multipath_shorter_than_cp_is_a_per_subcarrier_multiply():
    fft, cp = 64, 16
    x = _cn((2, 6, fft), 3)
    taps = _cn((2, cp + 1), 4) * torch.exp(-torch.arange(cp + 1) / 4.0)  # 17 taps = CP + 1
    y = apply_taps(phy.ofdm_modulate(x, cp), taps)
    Y = phy.ofdm_demodulate(y, fft, cp)
    H = taps_frequency_response(taps, fft)[:, None, :]  # [batch, 1, fft_size]
    # the first symbol is also clean: the zeros before the stream act as its prefix's past
    torch.testing.assert_close(Y, H * x, atol=1e-4, rtol=0)


def test_multipath_longer_than_cp_is_not():
    fft, cp = 64, 4
    x = _cn((1, 6, fft), 5)
    taps = torch.zeros(1, 12, dtype=torch.complex64)
    taps[0, 0], taps[0, 11] = 1.0, 0.7
    Y = phy.ofdm_demodulate(apply_taps(phy.ofdm_modulate(x, cp), taps), fft, cp)
    err = (Y - taps_frequency_response(taps, fft)[:, None] * x)[:, 1:]
    assert err.abs().pow(2).mean() > 0.05  # inter-symbol interference


def test_map_extract_round_trip_and_pilots_in_place():
    g = phy.ResourceGrid()
    x = _cn((2, 2 * g.num_data_symbols), 6)
    grid = phy.map_to_grid(x, g)
    assert grid.shape == (2, 28, 64)
    torch.testing.assert_close(phy.extract_data(grid, g), x, atol=0, rtol=0)
    torch.testing.assert_close(grid[0, :14][g.pilot_mask], g.pilots, atol=0, rtol=0)
    unused = ~(g.pilot_mask | g.data_mask)
    assert (grid[:, :14][:, unused] == 0).all()


def test_interpolation_matrix_by_hand():
    w = phy.interpolation_matrix(np.array([0, 4]), np.array([-1, 0, 1, 2, 4, 6]))
    np.testing.assert_allclose(w, [[1, 0], [1, 0], [0.75, 0.25], [0.5, 0.5], [0, 1], [0, 1]])


def test_ls_estimate_is_exact_without_noise_on_a_flat_channel():
    g = phy.ResourceGrid(pilot_subcarrier_spacing=3)
    h = torch.tensor([0.3 - 1.1j, -0.8 + 0.2j], dtype=torch.complex64).reshape(2, 1, 1)
    y = h * phy.map_to_grid(_cn((2, g.num_data_symbols), 7), g)
    h_hat, err = phy.ls_channel_estimate(y, g, 0.0)
    used = torch.zeros(64, dtype=torch.bool)
    used[g.used_subcarriers] = True
    torch.testing.assert_close(h_hat[..., used], h.expand(2, 14, 52), atol=1e-6, rtol=0)
    assert (err == 0).all()


def test_ls_estimation_error_matches_its_stated_variance():
    g = phy.ResourceGrid(pilot_subcarrier_spacing=2, pilot_ofdm_symbols=(0, 7, 13))
    nv = 0.05
    gen = G().manual_seed(8)
    x = phy.map_to_grid(_cn((400, g.num_data_symbols), 9), g)
    out = phy.AWGN()(x, phy.noise_var_to_snr_db(nv), generator=gen)
    h_hat, err = phy.ls_channel_estimate(out.y, g, out.noise_var)
    used = g.used_subcarriers
    measured = (h_hat - 1)[..., used].abs().pow(2).mean(0)  # [14, 52]
    stated = err[0][..., used]
    # at a pilot: noise_var; midway between pilots in frequency: noise_var / 2
    assert stated[0, 0].item() == pytest.approx(nv) and stated[0, 1].item() == pytest.approx(nv / 2)
    # 400 draws per element: each mean has a relative s.d. of 1/sqrt(400) = 5 %
    assert measured.mean().item() == pytest.approx(stated.mean().item(), rel=0.02)
    assert (measured / stated - 1).abs().max() < 0.25


@pytest.mark.parametrize("csi", ["perfect", "ls"])
@pytest.mark.parametrize("name", ["awgn", "rayleigh", "rician"])
def test_ofdm_link_reports_its_noise_truthfully(name, csi):
    g = phy.ResourceGrid()
    gen = G().manual_seed(10)
    x = phy.power_normalize(_cn((100, 1500), 11))
    out = phy.OFDMLink(g, phy.make_channel(name), csi=csi, equalizer="mmse")(x, 10.0, generator=gen)
    assert out.x_hat.shape == x.shape and out.noise_var.shape == x.shape
    measured = (out.x_hat - x).abs().pow(2).mean().item()
    assert measured == pytest.approx(out.noise_var.mean().item(), rel=0.1)


def test_ofdm_link_is_differentiable_and_ls_costs_snr():
    g = phy.ResourceGrid()
    x = phy.power_normalize(_cn((4, 700), 12)).requires_grad_(True)
    perfect = phy.OFDMLink(g, phy.AWGN(), csi="perfect")(x, 5.0, generator=G().manual_seed(0))
    ls = phy.OFDMLink(g, phy.AWGN(), csi="ls")(x, 5.0, generator=G().manual_seed(0))
    (ls.x_hat.abs().pow(2).sum()).backward()
    assert x.grad is not None and x.grad.abs().sum() > 0
    assert ls.noise_var.mean() > perfect.noise_var.mean()


@pytest.mark.parametrize("name", ["tdl", "cdl"])
def test_tr38901_channels_unit_power_reproducible_and_frequency_selective(name):
    ch = phy.make_channel(name, model="A", delay_spread_s=300e-9)
    x = torch.ones(200, 2, 64, dtype=torch.complex64)
    a = ch(x, 30.0, generator=G().manual_seed(1))
    b = ch(x, 30.0, generator=G().manual_seed(1))
    assert torch.equal(a.h, b.h) and a.h.shape == x.shape
    p = a.h.abs().pow(2)
    assert abs(p.mean().item() - 1) < 0.15  # 200 realisations of a multi-tap profile
    # 300 ns spread over 64 x 15 kHz = 960 kHz: the gain varies across the band
    assert (p[:, 0].std(dim=-1) / p[:, 0].mean(dim=-1)).mean() > 0.05


def test_tdl_frequency_correlation_is_the_fourier_transform_of_its_profile():
    """E[H(f + df) conj(H(f))] = sum_l p_l exp(-2j pi df tau_l) / sum_l p_l (Rayleigh taps)."""
    ch = phy.TDLChannel("A", delay_spread_s=300e-9, subcarrier_spacing_hz=15e3, fft_size=64)
    h = ch(torch.ones(200, 1, 64, dtype=torch.complex64), 30.0, generator=G().manual_seed(4)).h[
        :, 0
    ]
    delays, powers = ch.power_delay_profile
    for lag in (2, 8):
        df = lag * 15e3
        theory = (powers * torch.exp(-2j * math.pi * df * delays)).sum() / powers.sum()
        measured = (h[:, lag:] * h[:, :-lag].conj()).mean() / h.abs().pow(2).mean()
        assert abs(measured - theory) < 0.05, (
            lag,
            measured,
            theory,
        )  # a sign error gives 0.1, 0.39


def test_tdl_through_ofdm_link_with_ls_estimation():
    g = phy.ResourceGrid(pilot_subcarrier_spacing=2)
    ch = phy.TDLChannel("C", delay_spread_s=100e-9, fft_size=g.fft_size, cp_length=g.cp_length)
    x = phy.power_normalize(_cn((50, 1000), 13))
    out = phy.OFDMLink(g, ch, csi="ls")(x, 15.0, generator=G().manual_seed(2))
    mse = (out.x_hat - x).abs().pow(2).mean().item()
    assert math.isfinite(mse) and mse == pytest.approx(out.noise_var.mean().item(), rel=0.25)


def test_bad_grid_and_link_arguments():
    with pytest.raises(ValueError, match="fft_size must be"):
        phy.ResourceGrid(fft_size=3)
    with pytest.raises(ValueError, match="cp_length must be"):
        phy.ResourceGrid(cp_length=-1)
    with pytest.raises(ValueError, match="pilot_ofdm_symbols must be"):
        phy.ResourceGrid(pilot_ofdm_symbols=(20,))
    with pytest.raises(ValueError, match="csi must be one of"):
        phy.OFDMLink(phy.ResourceGrid(), phy.AWGN(), csi="none")
    with pytest.raises(ValueError, match="model must be one of"):
        phy.TDLChannel(model="Z")
    with pytest.raises(ValueError, match="delay_spread_s"):
        phy.CDLChannel(delay_spread_s=-1.0)
