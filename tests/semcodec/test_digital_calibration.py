"""The honest digital link: the shipped calibration table's maths, no peeking at the draw,
the genie as a bound."""

import math

import numpy as np
import pytest
import torch
from scipy.integrate import quad
from smooth_images import smooth_image

import phy
from common import psnr
from phy.digital import MCS_TABLE, codeword_layout
from semcodec.digital import IMAGE_CODECS, transmit_digital
from semcodec.digital.calibration import (
    MEASURED,
    fade_grid,
    fit_probit,
    load_calibration,
    measured_lengths,
)


@pytest.fixture(scope="module")
def cal():
    return load_calibration()


def test_table_covers_every_mcs_measured_channel_and_codec(cal):
    for ch in MEASURED:
        assert set(cal.curves[ch]) == set(MCS_TABLE)
        for mcs in MCS_TABLE:
            assert {int(e) for e in cal.curves[ch][mcs]} == set(measured_lengths(ch, mcs))
    assert set(cal.rd) == set(IMAGE_CODECS)
    # thresholds rise with spectral efficiency (AWGN, longest codewords)
    t = [_longest(cal, "awgn", m)["t_db"] for m in MCS_TABLE]
    assert t == sorted(t)


def _longest(cal, channel, mcs):
    return cal.curves[channel][mcs][str(max(measured_lengths(channel, mcs)))]


def _shannon_db(mcs) -> float:
    """Es/N0 at which a complex Gaussian channel's capacity is the MCS's spectral efficiency."""
    return 10 * math.log10(2.0 ** MCS_TABLE[mcs].spectral_efficiency - 1.0)


@pytest.mark.parametrize("mcs", list(MCS_TABLE)[:12])
def test_low_rate_codes_decode_within_2_db_of_the_shannon_limit(cal, mcs):
    """QPSK at R = 30/1024 .. 1/3 (repeated rate-1/5 LDPC below 1/5): the AWGN threshold
    (50 % codeword errors, longest codewords) lies 0.7 to 2 dB above the Es/N0 where capacity
    equals the MCS's spectral efficiency; closer than 0.7 dB would mean a broken model."""
    gap = _longest(cal, "awgn", mcs)["t_db"] - _shannon_db(mcs)
    assert 0.7 < gap < 2.0, gap


def test_the_lowest_mcs_reaches_below_minus_12_db(cal):
    """TS 38.214's lowest QPSK entry, 30/1024, decodes half its codewords near -12.3 dB; at
    -10 dB an image of thousands of codewords at that MCS is almost never lost."""
    lowest = next(iter(MCS_TABLE))
    assert lowest == "qpsk-30/1024"
    assert -13.0 < _longest(cal, "awgn", lowest)["t_db"] < -11.5
    assert cal.image_bler("awgn", lowest, -10.0, 73728) < 1e-3


@pytest.mark.parametrize("name", [*sorted(phy.CHANNELS), "ota"])
def test_the_model_a_transmitter_assumes_for_every_channel_has_a_calibration(cal, name):
    """The transmitter plans with ``phy.assumed_channel``: the channel itself where phy
    draws it from a distribution, TDL-A for a ray-traced response or a radio link."""
    model = phy.assumed_channel(name)
    assert model in cal.source(model)
    assert model == (name if name in phy.CHANNELS and name != "raytraced" else "tdl")


def test_unknown_channel_lists_the_known_ones(cal):
    with pytest.raises(KeyError, match="known: .*rayleigh"):
        cal.image_bler("mars", "qpsk-1/2", 5.0, 1000)


@pytest.mark.parametrize(
    "mcs,snr_db,num_symbols",
    [("qpsk-1/2", 3.0, 1200), ("16qam-1/2", 12.0, 73728), ("64qam-3/4", 25.0, 20000)],
)
def test_block_rayleigh_bler_is_the_awgn_curve_averaged_over_exp1_fades(
    cal, mcs, snr_db, num_symbols
):
    """P(lost) = int_0^inf [1 - (1 - p_awgn(snr * g))^C] e^-g dg, by adaptive quadrature."""
    lay = codeword_layout(num_symbols, mcs)
    c, e = lay.num_codewords, lay.coded_bits(0)

    def lost(g):
        p = float(cal.codeword_bler("awgn", mcs, snr_db + 10 * math.log10(g), e))
        return (1.0 - (1.0 - p) ** c) * math.exp(-g)

    t = _longest(cal, "awgn", mcs)["t_db"]
    knee = 10 ** ((t - snr_db) / 10)  # where the fade crosses the threshold
    pts = [knee * f for f in (0.25, 0.5, 1.0, 2.0, 4.0)]
    ref = quad(lost, 1e-12, 60.0, points=pts, limit=400, epsabs=1e-10)[0]
    got = cal.image_bler("rayleigh", mcs, snr_db, num_symbols)
    assert got == pytest.approx(ref, rel=2e-3, abs=1e-6)
    # and the outage formula of a hard threshold at that knee is close: 1 - exp(-knee)
    assert got == pytest.approx(-math.expm1(-knee), rel=0.5)


def test_fade_grids_are_distributions_with_unit_mean_power():
    for kind in ("rayleigh", "rician"):
        gain_db, w = fade_grid(kind)
        assert w.sum() == pytest.approx(1.0) and (w >= 0).all()
        assert float(np.sum(w * 10 ** (gain_db / 10))) == pytest.approx(1.0, rel=2e-3)


def test_awgn_bler_has_no_fading_and_fades_cost_outages(cal):
    n = 4000
    for mcs in ("qpsk-30/1024", "qpsk-1/2", "16qam-3/4"):
        t = _longest(cal, "awgn", mcs)["t_db"]
        assert cal.image_bler("awgn", mcs, t + 3, n) < 1e-3
        assert cal.image_bler("rayleigh", mcs, t + 3, n) > 0.2  # deep fades
        assert cal.image_bler("awgn", mcs, t - 3, n) > 0.999


def test_probit_fit_recovers_its_parameters():
    rng = np.random.default_rng(0)
    x = np.linspace(-2, 2, 21)
    p = 0.5 * (1 - np.vectorize(math.erf)((x - 0.3) / (0.4 * math.sqrt(2))))
    k = rng.binomial(2000, p)
    t, s = fit_probit(x, k, np.full_like(x, 2000))
    assert t == pytest.approx(0.3, abs=0.02) and s == pytest.approx(0.4, abs=0.03)


def test_choice_rises_with_snr_and_deep_fades_make_it_cautious(cal):
    idx = list(MCS_TABLE).index
    n, px = 73728, 768 * 512
    awgn = [idx(cal.choose_mcs("awgn", s, n, px)[0]) for s in range(0, 26, 2)]
    assert awgn == sorted(awgn) and awgn[0] < awgn[-1]
    for s in (4.0, 10.0, 16.0):
        assert idx(cal.choose_mcs("rayleigh", s, n, px)[0]) <= idx(
            cal.choose_mcs("awgn", s, n, px)[0]
        )


def _link(name):
    return phy.FlatLink(phy.make_channel(name), csi="perfect", equalizer="zf")


def test_honest_digital_never_peeks_at_the_draw_and_the_genie_is_never_below_it():
    x = smooth_image(3, 32, 32)
    n = 32 * 32 * 3 // 4
    link = _link("rayleigh")
    honest, genie = [], []
    for d in range(6):
        a = transmit_digital(
            x, link, 6.0, n, mcs="auto", generator=torch.Generator().manual_seed(d)
        )
        b = transmit_digital(
            x, link, 6.0, n, mcs="genie", generator=torch.Generator().manual_seed(d)
        )
        honest.append(a)
        genie.append(b)
        assert psnr(b.images, x) >= psnr(a.images, x) - 1e-9
        assert a.stats["mcs_choice"] == "auto" and b.stats["mcs_choice"] == "genie (bound)"
    assert len({tuple(r.stats["mcs"]) for r in honest}) == 1  # one MCS for every draw
    lost = [r.stats["views_lost"] for r in honest]
    assert sum(v["channel"] for v in lost) >= 1  # block fading at 6 dB: some outages
    assert all(v["budget"] == 0 for v in lost)
    assert any(psnr(g.images, x) > psnr(h.images, x) for g, h in zip(genie, honest))


def test_budget_loss_is_told_apart_from_channel_loss():
    x = smooth_image(4, 32, 32)
    res = transmit_digital(x, _link("awgn"), 20.0, 30, mcs="qpsk-1/3")
    assert res.stats["views_lost"] == {"budget": 1, "channel": 0}
    res = transmit_digital(x, _link("awgn"), -5.0, 768, mcs="64qam-5/6")
    assert res.stats["views_lost"] == {"budget": 0, "channel": 1}


def test_envelope_is_the_genie_and_unknown_modes_list_the_known_ones():
    x = smooth_image(5, 32, 32)
    res = transmit_digital(x, _link("awgn"), 10.0, 768, mcs="envelope")
    assert res.stats["mcs_choice"] == "genie (bound)"
    with pytest.raises(KeyError, match="auto.*genie.*qpsk-1/3"):
        transmit_digital(x, _link("awgn"), 10.0, 768, mcs="best")


def test_honest_digital_needs_the_channel_kind_the_genie_does_not():
    class Opaque(phy.AWGN):  # a channel of someone else's that does not say its kind
        kind = ""

    link = phy.FlatLink(Opaque(), csi="perfect", equalizer="zf")
    x = smooth_image(8, 32, 32)
    with pytest.raises(KeyError, match="pass channel="):
        transmit_digital(x, link, 10.0, 768, mcs="auto")
    assert (
        transmit_digital(x, link, 10.0, 768, mcs="auto", channel="awgn").stats["channel"] == "awgn"
    )
    res = transmit_digital(x, link, 10.0, 768, mcs="genie")
    assert res.stats["mcs_choice"] == "genie (bound)" and "calibration" not in res.stats


def test_rate_distortion_is_measured_at_every_scale_and_downscaling_reaches_lower_rates(cal):
    """Per scale, the lowest rate falls (fewer pixels to code) and the highest PSNR falls
    (the upscale cannot bring detail back); the hull over scales is the best of them."""
    for codec in IMAGE_CODECS:
        curves = {int(s): pts for s, pts in cal.rd[codec].items()}
        assert sorted(curves) == [1, 2, 4, 8, 16]
        low = [min(p["bpp"] for p in curves[s]) for s in sorted(curves)]
        top = [max(p["psnr_db"] for p in curves[s]) for s in sorted(curves)]
        assert low == sorted(low, reverse=True) and top == sorted(top, reverse=True)
    b = 0.01  # below the full-size curve's lowest rate: only downscaled images
    assert cal.psnr_at_bpp("avif", b, scales=[1]) == cal.lost_psnr_db
    assert cal.psnr_at_bpp("avif", b) == max(
        cal.psnr_at_bpp("avif", b, scales=[s]) for s in (2, 4, 8, 16)
    )
    assert cal.psnr_at_bpp("avif", b) > cal.lost_psnr_db + 5


def test_at_minus_10_db_the_honest_link_plans_a_downscaled_image_at_a_repeated_code(cal):
    """A Kodak image at CBR 1/16 and -10 dB AWGN: no full-size file fits any MCS that
    decodes, so with the full size alone the choice is a certain loss; with the scales the
    choice is a rate below 1/5 and a downscaled image."""
    n, px = 73728, 768 * 512
    smallest = {1: 1900, 2: 560, 4: 160, 8: 60, 16: 22}  # kodim01's, in bytes
    mcs, expected = cal.choose_mcs("awgn", -10.0, n, px, "avif", smallest)
    assert MCS_TABLE[mcs].code_rate < 0.2 and expected > cal.lost_psnr_db + 5
    assert cal.choose_mcs("awgn", -10.0, n, px, "avif", 1900)[1] == cal.lost_psnr_db


def test_the_link_records_the_scale_it_sent_and_the_image_round_trips_at_it():
    """256 px at CBR 1/16 over AWGN at -10 dB: the transmitter sends a downscaled image at a
    repeated code, the receiver upscales it, and the result says which scale and filter. The
    picture varies on a 64 px scale, so a downscaled copy keeps most of it."""
    base = torch.rand(1, 3, 4, 4, generator=torch.Generator().manual_seed(9))
    x = torch.nn.functional.interpolate(base, size=(256, 256), mode="bilinear").clamp(0, 1)
    res = transmit_digital(x, _link("awgn"), -10.0, 256 * 256 * 3 // 16, mcs="auto")
    st = res.stats
    assert st["lost_images"] == 0 and st["scale"][0] > 1 and st["resample_filter"] == "lanczos"
    assert MCS_TABLE[st["mcs"][0]].code_rate < 0.2
    assert psnr(res.images, x) > 25


@pytest.mark.parametrize("mcs,snr_db", [("qpsk-1/2", 1.0), ("16qam-1/2", 6.0), ("qpsk-1/3", -3.0)])
def test_loss_over_an_estimate_error_is_the_loss_averaged_over_a_gaussian(cal, mcs, snr_db):
    """Planning from an estimate with a Gaussian error of S dB: P(lost) = int phi(z)
    [1 - (1 - p(snr + S z))^C] dz (adaptive quadrature); S = 0 is the exact-knowledge value,
    to the bit."""
    n = 512 * 768 * 3 // 16
    lay = codeword_layout(n, mcs)
    c, e = lay.num_codewords, lay.coded_bits(0)
    s = 2.0

    def lost(z):
        p = float(cal.codeword_bler("awgn", mcs, snr_db + s * z, e))
        return (1.0 - (1.0 - p) ** c) * math.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)

    t = _longest(cal, "awgn", mcs)["t_db"]
    ref = quad(lost, -8, 8, points=[(t - snr_db) / s], limit=400, epsabs=1e-10)[0]
    assert cal.image_bler("awgn", mcs, snr_db, n, s) == pytest.approx(ref, rel=5e-3, abs=1e-5)
    assert cal.image_bler("awgn", mcs, snr_db, n, 0.0) == cal.image_bler("awgn", mcs, snr_db, n)
    # block fading: the error and the fade average together; with the error the loss is no
    # less than the fade's alone (within 0.02)
    both = cal.image_bler("rayleigh", mcs, snr_db, n, s)
    assert both >= cal.image_bler("rayleigh", mcs, snr_db, n) - 0.02


def test_an_uncertain_planner_backs_off_and_prices_the_lost_image(cal):
    """With an error on its estimate the planner never picks a faster MCS than when it trusts
    it, backs off somewhere, and forecasts the loss of its choice as its image BLER."""
    n_px = 512 * 768
    n = n_px * 3 // 16
    names = list(MCS_TABLE)
    backed_off = 0
    for snr in (-4.0, 0.0, 4.0, 7.0, 10.0, 13.0):
        exact, _ = cal.choose_mcs("awgn", snr, n, n_px)
        unsure, v = cal.choose_mcs("awgn", snr, n, n_px, snr_error_db=2.0)
        assert names.index(unsure) <= names.index(exact), snr
        backed_off += unsure != exact
        forecast = cal.image_loss("awgn", unsure, snr, n, snr_error_db=2.0)
        assert forecast == cal.image_bler("awgn", unsure, snr, n, 2.0)
        assert v == pytest.approx(
            cal.expected_psnr("awgn", unsure, snr, n, n_px, snr_error_db=2.0), abs=1e-12
        )
    assert backed_off >= 3
