"""Power after normalisation is exactly 1 per image; the SNR the decoder sees is the one applied."""

import math

import pytest
import torch

import phy
from semcodec.jscc import features_to_symbols, learned_only
from semcodec.jscc.channels import channel_mask, masked_transmit


def test_encoded_power_is_one_per_image(tiny_codec):
    g = torch.Generator().manual_seed(1)
    x = torch.rand(3, 3, 32, 48, generator=g)
    x[1] *= 0.01  # a nearly black image must still get unit power
    for cbr in (1 / 48, 1 / 16, 1 / 6):
        enc = learned_only(tiny_codec).encode(x, 5.0, cbr)
        p = (enc.symbols.abs() ** 2).mean(dim=1)
        assert enc.symbols.dtype == torch.complex64
        torch.testing.assert_close(p, torch.ones(3), rtol=1e-5, atol=1e-5)
        # with the analog layer where it is chosen: its float16 power scale is the
        # side information, so its power is 1 to within float16's 2**-11 relative step
        enc = tiny_codec.encode(x, 5.0, cbr)
        p = (enc.symbols.abs() ** 2).mean(dim=1)
        torch.testing.assert_close(p, torch.ones(3), rtol=1e-3, atol=0)


def test_masked_normalisation_equals_phy_power_normalize():
    """The per-image variable-rate normalisation used in training == phy.power_normalize of the kept
    symbols."""
    g = torch.Generator().manual_seed(2)
    feat = (
        torch.randn(3, 16, 5, 7, generator=g) * torch.tensor([1.0, 3.0, 0.2])[:, None, None, None]
    )
    m = torch.tensor([1, 3, 8])
    z, side, _ = masked_transmit(feat, m, torch.full((3,), 60.0), "awgn", g, 8)
    for i in range(3):
        want = phy.power_normalize(features_to_symbols(feat[i : i + 1], int(m[i])))
        got = features_to_symbols(z[i : i + 1], int(m[i]))
        torch.testing.assert_close(got, want, atol=5e-3, rtol=0)  # noise at 60 dB: std 1e-3
        assert torch.all(z[i, 2 * int(m[i]) :] == 0)
    assert side[:, 1].tolist() == pytest.approx([1 / 8, 3 / 8, 1.0])


@pytest.mark.parametrize("snr_db", [-3.0, 1.0, 10.0])
def test_measured_snr_equals_applied(snr_db):
    """Noise power per complex symbol of the unbiased symbols behind the decoder's LMMSE input
    = 10**(-snr/10) (1 %), and the reliability is 1 / (1 + noise_var) exactly."""
    g = torch.Generator().manual_seed(3)
    feat = torch.randn(4, 16, 64, 64, generator=g)
    m = torch.full((4,), 8)
    ref, _, rel_ref = masked_transmit(
        feat, m, torch.full((4,), 200.0 / 4), "awgn", None, 8
    )  # 50 dB: ~noise-free
    z, side, rel = masked_transmit(feat, m, torch.full((4,), snr_db), "awgn", g, 8)
    want = 10 ** (-snr_db / 10)
    torch.testing.assert_close(rel, torch.full_like(rel, 1 / (1 + want)))
    ref = ref / rel_ref.repeat_interleave(2, dim=1)  # LMMSE -> unbiased
    z = z / rel.repeat_interleave(2, dim=1)
    n = 4 * 8 * 64 * 64  # complex symbols
    noise_power = float(((z - ref) ** 2).sum()) / n  # per complex symbol (both real dims)
    signal_power = float((ref**2).sum()) / n
    assert signal_power == pytest.approx(1.0, rel=1e-3)
    # 4 sigma of the variance estimate over 2n real samples: sqrt(2/(2n))
    assert noise_power == pytest.approx(want, rel=4 * math.sqrt(1 / n) + 1e-3)
    assert side[:, 0].tolist() == pytest.approx([snr_db / 10] * 4)


def test_measured_snr_through_codec_and_phy_link(tiny_codec):
    g = torch.Generator().manual_seed(4)
    x = torch.rand(2, 3, 64, 64, generator=g)
    enc = tiny_codec.encode(x, 4.0, 1 / 6)
    link = phy.FlatLink(phy.make_channel("awgn"))
    out = link(enc.symbols, 4.0, generator=g)
    err = (out.x_hat - enc.symbols).abs() ** 2
    n = err.numel()
    assert float(err.mean()) == pytest.approx(10 ** (-0.4), rel=4 / math.sqrt(n))
    measured_snr_db = 10 * math.log10(float((enc.symbols.abs() ** 2).mean()) / float(err.mean()))
    assert measured_snr_db == pytest.approx(4.0, abs=4 * 4.343 / math.sqrt(n))


def test_channel_mask_keeps_exactly_m():
    mask = channel_mask(torch.tensor([1, 3, 8]), 8)[:, :, 0, 0]
    assert mask.sum(dim=1).tolist() == [2.0, 6.0, 16.0]
    assert mask[1].tolist() == [1.0] * 6 + [0.0] * 10


@pytest.mark.parametrize(
    "channel", ["rayleigh", "rayleigh_fast", "rayleigh_nocsi", "ofdm_rayleigh_ls"]
)
def test_training_channels_are_differentiable(channel):
    g = torch.Generator().manual_seed(5)
    feat = torch.randn(2, 16, 4, 4, generator=g, requires_grad=True)
    z, side, rel = masked_transmit(
        feat, torch.tensor([2, 8]), torch.tensor([5.0, 15.0]), channel, g, 8
    )
    assert z.shape == feat.shape and torch.all(z[0, 4:] == 0)
    assert rel.shape == (2, 8, 4, 4) and torch.all(rel[0, 2:] == 0)
    assert float(rel.detach().min()) >= 0 and float(rel.detach().max()) <= 1
    z.sum().backward()
    assert feat.grad is not None and torch.isfinite(feat.grad).all()
    assert torch.all(torch.isfinite(side))


def test_fast_fading_reliability_follows_each_fade():
    """Rayleigh fast with perfect CSI: reliability = |h|^2 snr / (1 + |h|^2 snr) per symbol, so
    its mean over many symbols matches E[g/(g + nv)] for g ~ Exp(1) (closed form via E1)."""
    from scipy.special import exp1

    g = torch.Generator().manual_seed(6)
    feat = torch.randn(2, 16, 32, 32, generator=g)
    snr_db = 4.0
    _, _, rel = masked_transmit(
        feat, torch.tensor([8, 8]), torch.full((2,), snr_db), "rayleigh_fast", g, 8
    )
    nv = 10 ** (-snr_db / 10)
    # w = g/(g + nv) with unit-power symbols; E[nv/(g+nv)] = nv e^{nv} E1(nv)
    want = 1 - nv * math.exp(nv) * exp1(nv)
    assert float(rel.mean()) == pytest.approx(want, abs=0.01)
    assert float(rel.std()) > 0.1  # one reliability per symbol, not per image


def test_version1_decoder_sees_awgn_like_symbols(tiny_codec):
    """A version-1 decoder given per-symbol noise variances: uniform nv is exactly the AWGN
    decode at SNR 1/nv (nothing rescaled); non-uniform nv gets the effective SNR from the mean
    reliability and relative-LMMSE scaling (1 + nv_eff) / (1 + nv_i)."""
    g = torch.Generator().manual_seed(7)
    x = torch.rand(2, 3, 32, 32, generator=g)
    enc = tiny_codec.encode(x, 5.0, 1 / 16)
    y = enc.symbols + 0.3 * torch.randn(enc.symbols.shape, generator=g, dtype=torch.complex64)
    nv = torch.full(enc.symbols.shape, 0.25)
    a = tiny_codec.decode(y, enc.meta, 0.0, noise_var=nv)
    b = tiny_codec.decode(y, enc.meta, 10 * math.log10(4.0))
    torch.testing.assert_close(a, b)
    nv2 = nv.clone()
    nv2[:, ::2] = 3.0  # half the symbols in deep fades
    w = 1 / (1 + nv2)
    nv_eff = 1 / w.mean(1, keepdim=True) - 1
    scaled = y * ((1 + nv_eff) * w)
    snr_eff = (-10 * torch.log10(nv_eff[:, 0])).tolist()
    want = torch.cat([tiny_codec.decode(scaled[i : i + 1], enc.meta, snr_eff[i]) for i in range(2)])
    torch.testing.assert_close(tiny_codec.decode(y, enc.meta, 0.0, noise_var=nv2), want)
