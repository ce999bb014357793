"""SoftCast's maths: unit power, metadata in the budget, the LLSE's closed form, no cliff."""

import math

import numpy as np
import pytest
import torch
from smooth_images import smooth_image

import phy
from common import psnr
from semcodec.links import transmit_softcast
from semcodec.links.softcast import (
    VARIANCE_BITS,
    decode_chunks,
    encode_chunks,
    llse_gain,
    metadata_bits,
    plan_image,
)


@pytest.fixture(scope="module")
def kodak_crop(shared_data):
    from semcodec.links.schemes import load_image_folder

    _, images = load_image_folder(shared_data / "kodak")
    return images[0][:, :, 100:228, 200:392].contiguous()  # [1, 3, 128, 192]


def test_symbols_have_unit_power_and_the_metadata_is_charged(kodak_crop):
    budget = phy.num_symbols_for_cbr(1 / 16, 128, 192)
    plan, coeffs = plan_image(kodak_crop[0], budget, chunks_per_side=8)
    sym = encode_chunks(coeffs, plan)
    assert float(sym.abs().pow(2).mean()) == pytest.approx(1.0, abs=1e-5)
    assert plan.metadata_bits == 3 * 64 + len(plan.kept) * VARIANCE_BITS + 3 * 16 + 32
    assert plan.metadata_bits == metadata_bits(3 * 64, len(plan.kept))
    # the analog symbols and the metadata's share the budget
    assert sym.shape[0] + plan.metadata_symbols <= budget
    assert plan.metadata_symbols == math.ceil(plan.metadata_bits / 0.5)  # 0.5 bit per symbol
    res = transmit_softcast(kodak_crop, phy.AWGN(), 10.0, budget, chunks_per_side=8)
    assert res.stats["num_symbols"] == sym.shape[0] + plan.metadata_symbols
    assert res.stats["side_info_bits"] == plan.metadata_bits
    # the kept chunks are the highest-variance ones: none dropped above any kept
    k, h, w = 8, 128, 192
    var = coeffs.reshape(3, k, h // k, k, w // k).transpose(0, 1, 3, 2, 4).reshape(3 * k * k, -1)
    var = (var**2).mean(axis=1)
    dropped = np.setdiff1d(np.arange(3 * k * k), plan.kept)
    assert var[plan.kept].min() >= var[dropped].max()


def test_llse_mse_matches_its_closed_form():
    """A chunk of variance lambda scaled by g through noise sigma^2 per real dimension: the
    LLSE's MSE is lambda sigma^2 / (g^2 lambda + sigma^2)."""
    g = torch.Generator().manual_seed(0)
    n, lam, gain, sigma2 = 400_000, 2.5, 0.7, 0.3
    c = torch.randn(n, generator=g, dtype=torch.float64) * math.sqrt(lam)
    y = gain * c + torch.randn(n, generator=g, dtype=torch.float64) * math.sqrt(sigma2)
    est = llse_gain(gain, lam, sigma2) * y.numpy()
    mse = float(np.mean((est - c.numpy()) ** 2))
    want = lam * sigma2 / (gain**2 * lam + sigma2)
    se = want * math.sqrt(2.0 / n) * 3  # a chi-square-like spread, generously
    assert mse == pytest.approx(want, abs=4 * se)


def test_image_mse_matches_the_closed_form_over_draws(kodak_crop):
    """Pixel MSE (unclamped) averaged over AWGN draws = (energy of the dropped coefficients +
    sum over kept ones of (a g - 1)^2 c^2 + a^2 sigma^2) / pixels, an orthonormal chain."""
    budget = phy.num_symbols_for_cbr(1 / 16, 128, 192)
    plan, coeffs = plan_image(kodak_crop[0], budget, chunks_per_side=8)
    sym = encode_chunks(coeffs, plan)
    nv = 10 ** (-5 / 10)
    sigma2 = nv / 2
    kept_mask = np.zeros(coeffs.shape, bool)
    expected = 0.0
    for i, idx in enumerate(plan.kept):
        p, r, c = plan.chunk_slices(idx)
        kept_mask[p, r, c] = True
        a = llse_gain(plan.gains[i], plan.variances[i], sigma2)
        expected += float(np.sum((a * plan.gains[i] - 1) ** 2 * coeffs[p, r, c] ** 2))
        expected += a**2 * sigma2 * coeffs[p, r, c].size
    expected += float(np.sum(coeffs[~kept_mask] ** 2))
    expected /= coeffs.size
    g = torch.Generator().manual_seed(1)
    mses = []
    for _ in range(30):
        noise = torch.complex(
            torch.randn(sym.shape, generator=g), torch.randn(sym.shape, generator=g)
        ) * math.sqrt(nv / 2)
        rec = decode_chunks(sym + noise, torch.full(sym.shape, nv), plan)
        mses.append(float(((rec.double() - kodak_crop[0].double()) ** 2).mean()))
    assert np.mean(mses) == pytest.approx(expected, rel=0.01)


def test_psnr_rises_with_snr_at_every_step_without_a_cliff(kodak_crop):
    link = phy.channel_link("awgn")
    budget = phy.num_symbols_for_cbr(1 / 16, 128, 192)
    p = [
        psnr(
            transmit_softcast(kodak_crop, link, s, budget, torch.Generator().manual_seed(0)).images,
            kodak_crop,
        )
        for s in (-6.0, -3.0, 0.0, 3.0, 6.0, 10.0, 15.0)
    ]
    steps = np.diff(p)
    assert (steps > 0).all(), p
    assert steps.max() < 3.0, p  # graceful: no jump of a code's threshold


def test_tiny_images_fall_back_to_fewer_chunks():
    x = smooth_image(0, 32, 32)
    res = transmit_softcast(x, phy.AWGN(), 10.0, 512)
    assert res.stats["num_symbols"] <= 512 and res.stats["chunks"][0] < 3 * 24 * 24


def test_framed_softcast_decodes_its_frames_and_a_lost_frame_costs_only_its_chunks(kodak_crop):
    """Over a framed link (osnerf ota): with every frame the LLSE recovers the image as well
    as the link-level scheme at the same noise; a lost frame leaves finite pixels and costs
    quality, not the image."""
    from semcodec.links import FramedSettings, ReceivedBlock
    from semcodec.links.schemes import LINK_SCHEMES

    framed = LINK_SCHEMES["softcast"].framed
    settings = FramedSettings(snr_db=20.0, symbols_per_frame=256, cbr=1 / 16)
    images = kodak_crop.numpy()
    blocks, state = framed.transmit(images, settings)
    sym = blocks[0]
    nv = 10 ** (-20 / 10)
    g = np.random.default_rng(0)
    noise = (g.standard_normal(sym.shape) + 1j * g.standard_normal(sym.shape)) * np.sqrt(nv / 2)
    frames = -(-sym.shape[0] // 256)
    full = ReceivedBlock(
        (sym + noise).astype(np.complex64), np.full(sym.shape, nv, np.float32), [True] * frames
    )
    lost = ReceivedBlock(full.x_hat.copy(), full.noise_var.copy(), [False] + [True] * (frames - 1))
    lost.x_hat[:256] = 0
    (ok,) = framed.receive([full], state, images, settings)
    (one_lost,) = framed.receive([lost], state, images, settings)
    link_level = transmit_softcast(kodak_crop, phy.AWGN(), 20.0, ok.stats["symbol_budget"])
    assert ok.psnr == pytest.approx(psnr(link_level.images, kodak_crop), abs=0.3)
    assert np.isfinite(one_lost.image).all()
    assert 10.0 < one_lost.psnr < ok.psnr
    assert ok.stats["num_symbols"] <= ok.stats["symbol_budget"]


def test_a_budget_under_one_chunk_sends_the_means_and_none_refuses():
    """Under one chunk and its metadata the image arrives as its colour means; under the
    means' metadata nothing can be sent (ValueError)."""
    x = smooth_image(0, 32, 32)
    res = transmit_softcast(x, phy.AWGN(), 0.0, 238)
    assert res.stats["chunks_kept"] == [0] and res.stats["num_symbols"] <= 238
    means = x.mean(dim=(2, 3), keepdim=True).expand_as(x)
    assert torch.allclose(res.images, means, atol=1e-5)
    with pytest.raises(ValueError, match="hold no chunk"):
        transmit_softcast(x, phy.AWGN(), 0.0, 100)
