"""Transmitter-side refinement of the JSCC symbols (semcodec.jscc.refine_symbols, jscc_refined)."""

import math

import pytest
import torch
from smooth_images import smooth_image

import phy
from semcodec import LINK_SCHEMES, load_codec
from semcodec.jscc import refine_symbols, transmit_jscc
from semcodec.links.schemes import EvalContext


@pytest.fixture(scope="module")
def codec():
    return load_codec()  # the shipped model: refinement is only meaningful for a trained one


def _mean_psnr(codec, x, enc, link, snr, seeds) -> float:
    """Mean PSNR over the same evaluation draws (common random numbers)."""
    out = []
    for s in seeds:
        y = transmit_jscc(
            codec, x, link, snr, 1 / 16, generator=torch.Generator().manual_seed(s), encoded=enc
        ).images
        out.append(-10 * math.log10(float(((y - x) ** 2).mean())))
    return sum(out) / len(out)


def test_refinement_lowers_distortion_on_unseen_draws_and_keeps_power(codec):
    x = smooth_image(3, 64, 64)
    link = phy.FlatLink(phy.make_channel("rayleigh"), csi="perfect", equalizer="zf")
    snr = 10.0
    enc = codec.encode(x, snr, 1 / 16)
    weights = {k: v.clone() for k, v in codec.model.state_dict().items()}
    tx = torch.Generator().manual_seed(7)
    ref = refine_symbols(codec, x, enc, link, snr, steps=40, generator=tx)
    # same side information, same number of unit-power symbols
    assert ref.meta == enc.meta
    assert ref.symbols.shape == enc.symbols.shape and ref.symbols.dtype == torch.complex64
    assert float(ref.symbols.abs().pow(2).mean()) == pytest.approx(1.0, rel=1e-5)
    assert not torch.allclose(ref.symbols, enc.symbols)
    # the knowledge base is untouched: weights, their grads and requires_grad flags
    for k, v in codec.model.state_dict().items():
        assert torch.equal(v, weights[k]), k
    assert all(p.grad is None for p in codec.model.parameters())
    # evaluated on draws the transmitter never saw (other seeds, other generator)
    seeds = range(1000, 1024)
    plain = _mean_psnr(codec, x, enc, link, snr, seeds)
    refined = _mean_psnr(codec, x, ref, link, snr, seeds)
    assert refined > plain + 0.1, (plain, refined)


def test_refinement_works_in_focus_mode(codec):
    x = smooth_image(4, 64, 64)
    mask = torch.zeros(1, 64, 64)
    mask[:, 16:48, 20:44] = 1.0
    link = phy.FlatLink(phy.make_channel("awgn"), csi="perfect", equalizer="zf")
    enc = codec.encode(x, 5.0, 1 / 24, mask=mask)
    assert enc.meta.crop is not None
    ref = refine_symbols(codec, x, enc, link, 5.0, steps=5, generator=torch.Generator())
    assert ref.meta == enc.meta and ref.symbols.shape == enc.symbols.shape
    y = codec.decode(ref.symbols, ref.meta, 30.0)
    assert y.shape == x.shape


def test_zero_steps_is_the_encoder_and_bad_settings_are_refused(codec):
    x = smooth_image(5, 32, 32)
    enc = codec.encode(x, 5.0, 1 / 16)
    link = phy.make_channel("awgn")
    assert refine_symbols(codec, x, enc, link, 5.0, steps=0) is enc
    with pytest.raises(ValueError, match="steps must be >= 0"):
        refine_symbols(codec, x, enc, link, 5.0, steps=-1)
    with pytest.raises(ValueError, match="lr must be > 0"):
        refine_symbols(codec, x, enc, link, 5.0, steps=1, lr=0.0)


def test_refined_scheme_draws_from_its_own_stream(codec):
    """jscc_refined refines once per image and SNR on its own seed: the evaluation generator
    gives the same draw to jscc and jscc_refined (common random numbers)."""
    x = smooth_image(6, 32, 32)
    ctx = EvalContext(channel="awgn", codec=codec, refine_steps=3, refine_seed=11)
    g1, g2 = torch.Generator().manual_seed(5), torch.Generator().manual_seed(5)
    LINK_SCHEMES["jscc_refined"](ctx, x, 5.0, 1 / 16, g1)
    LINK_SCHEMES["jscc"](EvalContext(channel="awgn", codec=codec), x, 5.0, 1 / 16, g2)
    assert torch.equal(g1.get_state(), g2.get_state())
    assert (
        LINK_SCHEMES["jscc_refined"].bound is None and LINK_SCHEMES["jscc_refined"].kind == "jscc"
    )


def test_pixel_weights_spend_the_refinement_where_they_point(codec):
    """Weighted to one quarter of the picture, refinement lowers that quarter's error more
    than uniform refinement does (same steps, same transmitter draws, unseen test draws)."""
    x = smooth_image(8, 64, 64)
    link = phy.FlatLink(phy.make_channel("awgn"), csi="perfect", equalizer="zf")
    enc = codec.encode(x, 4.0, 1 / 16)
    w = torch.zeros(1, 1, 64, 64)
    w[..., :32, :32] = 1.0
    refined = {
        name: refine_symbols(
            codec,
            x,
            enc,
            link,
            4.0,
            steps=40,
            generator=torch.Generator().manual_seed(1),
            pixel_weights=weights,
        )
        for name, weights in (("uniform", None), ("quarter", w))
    }
    err = {}
    for name, e in refined.items():
        mse = []
        for s in range(2000, 2016):
            y = transmit_jscc(
                codec, x, link, 4.0, 1 / 16, generator=torch.Generator().manual_seed(s), encoded=e
            ).images
            mse.append(float(((y - x)[..., :32, :32] ** 2).mean()))
        err[name] = sum(mse) / len(mse)
    assert err["quarter"] < 0.9 * err["uniform"], err
