"""Baselines: budget bisection, ideal/analog limits, digital lost image = grey, registry."""

import math

import pytest
import torch
from smooth_images import smooth_image

import phy
from common import psnr
from semcodec import LINK_SCHEMES, LOST_IMAGE_VALUE
from semcodec.digital import (
    IMAGE_CODECS,
    encode_image,
    encode_to_budget,
    transmit_digital,
    transmit_ideal,
)
from semcodec.links import transmit_analog
from semcodec.links.schemes import EvalContext


@pytest.mark.parametrize("codec", sorted(IMAGE_CODECS))
def test_budget_bisection_is_maximal(codec):
    x = smooth_image(0, 48, 64)[0]
    budget = 600
    data, q = encode_to_budget(x, budget, codec)
    assert data is not None and len(data) <= budget
    hi = IMAGE_CODECS[codec].quality_range[1]
    if q < hi:  # the next quality would not fit
        assert len(encode_image(x, codec, q + 1)) > budget
    assert encode_to_budget(x, 10, codec) == (None, None)


def test_ideal_budget_is_capacity():
    x = smooth_image(0, 48, 64)
    n = 300
    res = transmit_ideal(x, 10.0, n)
    assert res.stats["budget_bits"] == math.floor(n * math.log2(11.0))
    assert res.stats["bits"] <= res.stats["budget_bits"]


def test_analog_is_exact_at_high_snr_and_noisy_at_low():
    x = smooth_image(0, 48, 64)
    link = phy.FlatLink(phy.make_channel("awgn"))
    g = torch.Generator().manual_seed(0)
    assert psnr(transmit_analog(x, link, 50.0, generator=g).images, x) > 45
    low = transmit_analog(x, link, 0.0, generator=g)
    assert 5 < psnr(low.images, x) < 30


def test_digital_lost_image_is_grey_and_good_link_is_codec_quality():
    x = smooth_image(1, 64, 64)
    n = round(64 * 64 * 3 / 6)
    link = phy.FlatLink(phy.make_channel("awgn"), equalizer="zf")
    bad = transmit_digital(
        x, link, -10.0, n, mcs="64qam-5/6", generator=torch.Generator().manual_seed(0)
    )
    assert bad.stats["lost_images"] == 1 and bad.stats["failed_codewords"] >= 1
    assert torch.all(bad.images == LOST_IMAGE_VALUE)
    good = transmit_digital(
        x, link, 30.0, n, mcs="16qam-1/2", generator=torch.Generator().manual_seed(0)
    )
    assert good.stats["lost_images"] == 0 and good.stats["failed_codewords"] == 0
    from phy.digital import payload_capacity_bits
    from semcodec.digital.image_codecs import encode_scaled_to_budget
    from semcodec.digital.link import decode_or_grey

    budget = payload_capacity_bits(n, "16qam-1/2") // 8
    data, _, scale = encode_scaled_to_budget(x[0], budget, "avif")
    assert good.stats["bits"] == 8 * len(data) <= payload_capacity_bits(n, "16qam-1/2")
    assert good.stats["scale"] == [scale]
    assert psnr(good.images, x) > 25
    # the file sent is at least as good as the best full-size one that fits
    full, _ = encode_to_budget(x[0], budget, "avif")
    assert psnr(good.images, x) >= psnr(decode_or_grey(full, x[0].shape, "avif")[0], x[0])


def test_scheme_registry_runs_every_name_and_bounds_bound(tiny_codec):
    """Every link-level scheme sends the same images on the same draws; a bound is never
    below the system it bounds (the genie keeps the best MCS that decodes on the draw; the
    capacity bound has at least the bits any MCS carries error free)."""
    ctx = EvalContext(channel="awgn", codec=tiny_codec, fixed_mcs="64qam-3/4")
    x = smooth_image(1, 32, 32)
    score = {}
    for name, fn in LINK_SCHEMES.items():
        res = fn(ctx, x, 6.0, 1 / 6, torch.Generator().manual_seed(0))
        assert res.images.shape == x.shape and res.images.dtype == torch.float32, name
        assert float(res.images.min()) >= 0 and float(res.images.max()) <= 1, name
        score[name] = psnr(res.images, x)
    for codec in ("", "_webp", "_jpeg"):
        assert score["ideal" + codec] >= score["digital" + codec] - 1e-9, (codec, score)
    assert score["digital_genie"] >= score["digital"] - 1e-9, score
    assert score["digital_genie"] >= score["digital_fixed"] - 1e-9, score
