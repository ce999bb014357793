"""The analog refinement layer (semcodec.jscc.analog) and the codec's split between learned
channels and the layer."""

import math

import pytest
import torch
from smooth_images import smooth_image

import phy
from semcodec import load_codec
from semcodec.jscc import for_fusion, learned_only, transmit_jscc
from semcodec.jscc.analog import (
    FORMAT_BITS,
    POWER_SCALE_BITS,
    REFERENCE_BITS,
    VAR_BITS,
    AnalogSide,
    chunk_grid,
    chunk_index,
    decode_residual,
    encode_residual,
    inverse_transform,
    layer_symbols,
    max_sent_chunks,
    side_symbols,
    transform,
)


def _dct_energy_residual(h, w, log2_energies, seed=0):
    """A residual whose DCT chunks have exactly the mean energies 2**log2_energies[k]."""
    chunk = chunk_index(h, w, chunk_grid(h, w))
    coef = torch.randn(3 * h * w, generator=torch.Generator().manual_seed(seed))
    for k, e in enumerate(log2_energies):
        sel = chunk == k
        coef[sel] *= math.sqrt(2.0**e / float(coef[sel].pow(2).mean()))
    return inverse_transform(coef[None], h, w), coef, chunk


def test_transform_is_orthonormal():
    x = torch.randn(2, 3, 24, 40, generator=torch.Generator().manual_seed(1))
    c = transform(x)
    assert float(c.pow(2).sum()) == pytest.approx(float(x.pow(2).sum()), rel=1e-5)
    assert torch.allclose(inverse_transform(c, 24, 40), x, atol=1e-5)


def test_noiseless_layer_with_every_coefficient_is_exact_and_unit_power():
    x = torch.randn(1, 3, 16, 24, generator=torch.Generator().manual_seed(2)) * 0.05
    n = 3 * 16 * 24 // 2
    sym, side = encode_residual(x, n)
    assert sym.shape == (1, n) and sym.dtype == torch.complex64
    assert float(sym.abs().pow(2).mean()) == pytest.approx(1.0, rel=2e-3)  # float16 scale
    assert torch.allclose(decode_residual(sym, torch.zeros(1, n), side), x, atol=1e-5)
    # every chunk sent: all 48 energies are the cheapest format
    bits = FORMAT_BITS + 3 * chunk_grid(16, 24) ** 2 * VAR_BITS + REFERENCE_BITS + POWER_SCALE_BITS
    assert side.side_info_bits() == bits
    assert side_symbols(16, 24, n) == math.ceil(side.side_info_bits() / 0.5)


def test_side_information_lists_only_the_sent_chunks_and_the_receiver_rebuilds_the_plan():
    h, w = 40, 60  # G = 4: 48 chunks of 10 x 15 = 150 coefficients
    fixed = FORMAT_BITS + REFERENCE_BITS + POWER_SCALE_BITS
    # 160 symbols = 320 reals touch at most 3 chunks: 3 (index, code) pairs of 6 + 6 bits
    assert max_sent_chunks(h, w, 160) == 3 and max_sent_chunks(h, w, 150) == 2
    side_bits = fixed + 3 * (6 + VAR_BITS)
    assert side_symbols(h, w, 160) == math.ceil(side_bits / 0.5)
    # 30 chunks: a bitmap of 48 and 30 codes beats 30 pairs and 48 codes
    assert side_symbols(h, w, 30 * 75) == math.ceil((fixed + 48 + 30 * VAR_BITS) / 0.5)
    # the layer and its side information fill the available symbols and no more
    for available in (100, 1000, 3000, 3 * h * w):
        n = layer_symbols(h, w, available)
        assert n + side_symbols(h, w, n) <= available
        assert n == 3 * h * w // 2 or n + 1 + side_symbols(h, w, n + 1) > available
    assert layer_symbols(h, w, 20) == 0
    res, _, _ = _dct_energy_residual(h, w, [-10 - (k * 7) % 13 for k in range(48)], seed=5)
    res = torch.cat([res, res.flip(-1)])  # two images, different chunk rankings
    sym, side = encode_residual(res, 160)
    index, codes = side.sent_chunks()
    assert index.shape == (2, 3)
    rx = AnalogSide.from_sent_chunks(h, w, 160, index, codes, side.power_scale)
    for a, b in zip(rx.sent_coefficients(), side.sent_coefficients(), strict=True):
        assert torch.equal(a, b)
    noise = torch.randn(
        sym.shape, generator=torch.Generator().manual_seed(6), dtype=torch.complex64
    )
    y = sym + 0.3 * noise
    assert torch.equal(decode_residual(y, 0.09, rx), decode_residual(y, 0.09, side))


def test_mse_matches_the_lmmse_formula_and_the_strongest_chunks_are_sent():
    h = w = 32  # G = 4: 48 chunks of 64 coefficients
    rng = torch.Generator().manual_seed(3)
    log2e = torch.randint(-16, -4, (48,), generator=rng).tolist()
    res, coef, chunk = _dct_energy_residual(h, w, log2e)
    n = 20 * 64 // 2  # the 20 strongest chunks
    sym, side = encode_residual(res, n)
    nv = 0.1  # 10 dB per complex symbol
    g = side.sent_coefficients()[2][0]  # gain of each sent real
    order = side.sent_coefficients()[0][0]
    strongest = torch.argsort(
        torch.tensor(log2e, dtype=torch.float64), descending=True, stable=True
    )[:20]
    assert set(chunk[order].tolist()) == set(strongest.tolist())
    lam = torch.exp2(torch.tensor(log2e, dtype=torch.float32))[chunk[order]]
    sent_err = float((lam * (nv / 2) / (g**2 * lam + nv / 2)).sum())
    unsent = torch.ones(3 * h * w, dtype=torch.bool)
    unsent[order] = False
    expected = (sent_err + float(coef[unsent].pow(2).sum())) / (3 * h * w)
    draws = []
    gen = torch.Generator().manual_seed(4)
    for _ in range(300):
        noise = torch.randn(sym.shape, generator=gen, dtype=torch.complex64) * math.sqrt(nv)
        draws.append(
            float((decode_residual(sym + noise, torch.full((1, n), nv), side) - res).pow(2).mean())
        )
    assert sum(draws) / len(draws) == pytest.approx(expected, rel=0.03)


def test_fused_estimate_averages_better_over_views_than_each_views_lmmse():
    """K receptions of one residual, each decoded against noise_var / K and then averaged, is
    the LMMSE of their mean: its error is the closed form, below the average of the per-view
    LMMSE estimates (which keep each view's shrinkage), while each view alone is worse."""
    h = w = 32
    res, _, _ = _dct_energy_residual(h, w, [-6 - (k % 12) for k in range(48)], seed=7)
    n = 16 * 64 // 2
    sym, side = encode_residual(res, n)
    nv, views = 1.0, 8
    _, prior, g = side.sent_coefficients()
    prior, g = prior[0], g[0]
    gen = torch.Generator().manual_seed(8)
    fused, own, fused_single, own_single = [], [], [], []
    for _ in range(60):
        rx = [
            sym + torch.randn(sym.shape, generator=gen, dtype=torch.complex64) * math.sqrt(nv)
            for _ in range(views)
        ]
        f = [decode_residual(y, nv / views, side) for y in rx]
        o = [decode_residual(y, nv, side) for y in rx]
        fused.append(float((sum(f) / views - res).pow(2).mean()))
        own.append(float((sum(o) / views - res).pow(2).mean()))
        fused_single.append(float((f[0] - res).pow(2).mean()))
        own_single.append(float((o[0] - res).pow(2).mean()))
    mean = lambda v: sum(v) / len(v)  # noqa: E731
    assert mean(fused) < 0.8 * mean(own) and mean(fused_single) > mean(own_single)
    sent = prior * (nv / 2 / views) / (g**2 * prior + nv / 2 / views)  # LMMSE of the mean
    order = side.sent_coefficients()[0][0]
    unsent = float(transform(res).pow(2).sum()) - float(transform(res)[0, order].pow(2).sum())
    expected = (float(sent.sum()) + unsent) / (3 * h * w)
    assert mean(fused) == pytest.approx(expected, rel=0.1)


def test_bad_layer_size_is_refused():
    with pytest.raises(ValueError, match="num_symbols"):
        encode_residual(torch.zeros(1, 3, 8, 8), 97)


@pytest.fixture(scope="module")
def codec():
    return load_codec()


def _psnr(a, b):
    return -10 * math.log10(float(((a - b) ** 2).mean()))


def test_layer_spends_the_budget_and_beats_learned_channels_at_high_rate_and_snr(codec):
    x = smooth_image(5, 96, 128)
    budget = round(3 * 96 * 128 / 3)
    enc = codec.encode(x, 10.0, 1 / 3)
    meta = enc.meta
    assert meta.analog is not None and meta.num_channels < 16
    n_layer = meta.analog.num_symbols  # the side information is charged to the budget
    assert meta.num_symbols + side_symbols(96, 128, n_layer) <= budget
    assert meta.num_symbols + side_symbols(96, 128, n_layer + 1) + 1 > budget
    assert meta.base_symbols == meta.num_channels * 24 * 32
    assert float(enc.symbols.abs().pow(2).mean()) == pytest.approx(1.0, rel=2e-3)
    link = phy.FlatLink(phy.make_channel("awgn"), csi="perfect", equalizer="zf")
    out = {}
    for layer in (True, False):
        tx = codec if layer else learned_only(codec)
        ps = []
        for s in range(3):
            gen = torch.Generator().manual_seed(s)
            ps.append(_psnr(transmit_jscc(tx, x, link, 10.0, 1 / 3, generator=gen).images, x))
        out[layer] = sum(ps) / 3
    assert out[True] > out[False] + 1.0


def test_layer_decodes_per_symbol_noise_and_is_skipped_where_it_does_not_pay(codec):
    x = smooth_image(6, 64, 64)
    enc = codec.encode(x, 10.0, 1 / 3)
    n = enc.meta.num_symbols
    nv = torch.full((1, n), 0.1)
    nv[:, n // 2 :] = 1e9  # an erased half: those symbols carry nothing, decode stays finite
    y = codec.decode(enc.symbols, enc.meta, 10.0, noise_var=nv)
    assert torch.isfinite(y).all() and y.shape == x.shape
    low = codec.encode(x, -5.0, 1 / 16)  # low rate, low SNR: learned channels only
    assert low.meta.analog is None and low.meta.num_symbols == 3 * 16 * 16


def test_focus_box_gets_the_layer_at_its_offset(codec):
    x = smooth_image(7, 96, 128)
    mask = torch.zeros(1, 1, 96, 128)
    mask[:, :, 36:84, 60:124] = 1.0  # off-centre, so a misplaced residual would show
    budget_cbr = 1 / 3 * (48 * 64) / (96 * 128)  # CBR 1/3 over the box
    out = {}
    for layer in (True, False):
        enc = (codec if layer else learned_only(codec)).encode(x, 20.0, budget_cbr, mask=mask)
        y = codec.decode(enc.symbols, enc.meta, 20.0)  # noiseless: the layer's best case
        err = ((y - x) ** 2 * mask).sum() / (3 * mask.sum())
        out[layer] = (enc.meta, -10 * math.log10(float(err)))
    meta, psnr = out[True]
    assert meta.crop is not None and meta.analog is not None
    assert (meta.analog.height, meta.analog.width) == meta.crop[2:]
    assert psnr > out[False][1] + 2.0


def test_refinement_differentiates_through_the_layer(codec, shared_data):
    from semcodec.jscc import refine_symbols
    from semcodec.links.schemes import load_image_folder

    x = load_image_folder(shared_data / "kodak")[1][0][:, :, 128:256, 256:448]
    link = phy.FlatLink(phy.make_channel("awgn"), csi="perfect", equalizer="zf")
    enc = codec.encode(x, 10.0, 1 / 3)
    assert enc.meta.analog is not None
    ref = refine_symbols(codec, x, enc, link, 10.0, steps=30, generator=torch.Generator())
    n = enc.meta.base_symbols
    assert ref.meta == enc.meta
    assert float((ref.symbols[:, n:] - enc.symbols[:, n:]).abs().mean()) > 0  # layer moves too
    assert float(ref.symbols.abs().pow(2).mean()) == pytest.approx(1.0, rel=1e-4)

    def mean_psnr(e):
        ps = []
        for s in range(4):
            gen = torch.Generator().manual_seed(100 + s)
            y = transmit_jscc(codec, x, link, 10.0, 1 / 3, generator=gen, encoded=e).images
            ps.append(_psnr(y, x))
        return sum(ps) / 4

    assert mean_psnr(ref) > mean_psnr(enc)


def test_fusion_receiver_changes_only_the_layers_estimate(codec):
    x = smooth_image(5, 96, 128)
    enc = codec.encode(x, 10.0, 1 / 3)
    assert enc.meta.analog is not None
    assert for_fusion(codec, 1) is codec and for_fusion(learned_only(codec), 4).layer_fusion == 4
    rx = for_fusion(codec, 4)
    assert rx.layer_fusion == 4 and codec.layer_fusion == 1 and rx.sha256 == codec.sha256
    y = enc.symbols + 0.5 * torch.randn(
        enc.symbols.shape, generator=torch.Generator().manual_seed(9), dtype=torch.complex64
    )
    a, b = codec.decode(y, enc.meta, 10.0), rx.decode(y, enc.meta, 10.0)
    assert not torch.equal(a, b)
    # without the layer the decode is the learned decoder's, untouched
    enc = learned_only(codec).encode(x, 10.0, 1 / 3)
    y = enc.symbols + 0.5 * torch.randn(
        enc.symbols.shape, generator=torch.Generator().manual_seed(9), dtype=torch.complex64
    )
    assert torch.equal(codec.decode(y, enc.meta, 10.0), rx.decode(y, enc.meta, 10.0))
    for bad in (0.5, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="views"):
            for_fusion(codec, bad)


def test_transmitter_for_a_fusing_receiver_splits_towards_the_layer(codec):
    """Fused over many receptions the layer's noise averages down, so its split sends the
    layer where a single image would not, and fewer learned channels under it."""
    x = smooth_image(5, 96, 128)
    tx = for_fusion(codec, 100, "transmitter")
    assert tx.split_fusion == 100 and tx.layer_fusion == 1 and codec.split_fusion == 1
    alone, fused = codec.encode(x, -5.0, 1 / 12).meta, tx.encode(x, -5.0, 1 / 12).meta
    assert alone.analog is None and fused.analog is not None
    assert fused.num_channels < alone.num_channels
    with pytest.raises(ValueError, match="end"):
        for_fusion(codec, 4, "both")


def test_jscc_learned_scheme_sends_the_learned_channels_only(codec):
    from semcodec import LINK_SCHEMES
    from semcodec.links.schemes import EvalContext

    x = smooth_image(5, 96, 128)
    ctx = EvalContext(channel="awgn", codec=codec)
    with_layer = LINK_SCHEMES["jscc"](ctx, x, 10.0, 1 / 3, torch.Generator().manual_seed(0))
    learned = LINK_SCHEMES["jscc_learned"](ctx, x, 10.0, 1 / 3, torch.Generator().manual_seed(0))
    assert learned.stats["cbr"] == pytest.approx(1 / 3) and learned.stats["side_info_bits"] == 0
    assert with_layer.stats["side_info_bits"] > 0 and with_layer.stats["cbr"] < 1 / 3
    assert codec.analog_layer and not learned_only(codec).analog_layer  # a copy, not a switch
