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
from semcodec import IMAGE_CODECS, transmit_digital
from semcodec.digital_calibration import (
    MEASURED,
    fade_grid,
    fit_probit,
    load_calibration,
)


@pytest.fixture(scope="module")
def cal():
    return load_calibration()


def test_table_covers_every_mcs_measured_channel_and_codec(cal):
    for ch, lengths in MEASURED.items():
        assert set(cal.curves[ch]) == set(MCS_TABLE)
        for mcs in MCS_TABLE:
            assert {int(e) for e in cal.curves[ch][mcs]} == set(lengths)
    assert set(cal.rd) == set(IMAGE_CODECS)
    # thresholds rise with spectral efficiency (AWGN, longest codewords)
    t = [cal.curves["awgn"][m]["3840"]["t_db"] for m in MCS_TABLE]
    assert t == sorted(t)


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

    t = cal.curves["awgn"][mcs]["3840"]["t_db"]
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
    for mcs in ("qpsk-1/2", "16qam-3/4"):
        t = cal.curves["awgn"][mcs]["3840"]["t_db"]
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
