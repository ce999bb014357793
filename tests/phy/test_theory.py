"""Uncoded BER/SER against closed forms (within 4 sigma, >= 1000 errors) and the forms
themselves."""

import math

import numpy as np
import pytest
import torch
from scipy.integrate import quad
from scipy.stats import norm

import phy
from phy.ber import simulate_uncoded
from phy.modulation import bits_per_symbol, constellation, demap_hard, map_bits
from phy.theory import ber_theory, ser_theory

MODS = ["bpsk", "qpsk", "16qam", "64qam"]


def test_bpsk_and_qpsk_closed_forms_by_hand():
    g = 10**0.5  # 5 dB
    assert ber_theory("bpsk", 5.0) == pytest.approx(norm.sf(math.sqrt(2 * g)), rel=1e-12)
    assert ber_theory("qpsk", 5.0) == pytest.approx(norm.sf(math.sqrt(g)), rel=1e-12)
    q = norm.sf(math.sqrt(g))
    assert ser_theory("qpsk", 5.0) == pytest.approx(2 * q - q * q, rel=1e-12)
    assert ber_theory("bpsk", 5.0, "rayleigh") == pytest.approx(0.5 * (1 - math.sqrt(g / (1 + g))))


def test_16qam_ber_matches_the_textbook_gray_expression():
    # Gray 16-QAM exact BER (per-dimension 4-PAM, Gray): (3 Q(d) + 2 Q(3d) - Q(5d)) / 4, d =
    # sqrt(g/5)
    for s in (0.0, 8.0, 14.0):
        d = math.sqrt(10 ** (s / 10) / 5)
        ref = (3 * norm.sf(d) + 2 * norm.sf(3 * d) - norm.sf(5 * d)) / 4
        assert ber_theory("16qam", s) == pytest.approx(ref, rel=1e-10)


@pytest.mark.parametrize("mod", MODS)
def test_rayleigh_forms_equal_the_numerical_average_over_fading(mod):
    gbar = 10 ** (12 / 10)
    for f in (ber_theory, ser_theory):

        def awgn_at(g, f=f):
            return f(mod, 10 * math.log10(g), "awgn") * math.exp(-g / gbar) / gbar

        num = quad(awgn_at, 1e-9, 60 * gbar, limit=200)[0]
        assert f(mod, 12.0, "rayleigh") == pytest.approx(num, rel=1e-5)


@pytest.mark.parametrize("mod", MODS)
def test_constellations_have_unit_energy_and_gray_labels(mod):
    pts = constellation(mod)
    k = bits_per_symbol(mod)
    assert pts.shape == (2**k,)
    assert abs(pts.abs().pow(2).mean().item() - 1) < 1e-6
    # Gray: nearest neighbours differ in exactly one bit
    d = (pts[:, None] - pts[None, :]).abs()
    dmin = d[d > 0].min()
    for i, j in zip(*torch.nonzero((d - dmin).abs() < 1e-5, as_tuple=True)):
        assert bin(int(i) ^ int(j)).count("1") == 1


@pytest.mark.parametrize("mod", MODS)
def test_constellation_equals_sionnas(mod):
    from sionna.phy.mapping import Constellation

    kind = "pam" if mod == "bpsk" else "qam"
    ref = Constellation(kind, bits_per_symbol(mod), precision="single", device="cpu").points
    torch.testing.assert_close(constellation(mod), ref.to(torch.complex64), atol=1e-6, rtol=0)


@pytest.mark.parametrize("mod", MODS)
def test_map_then_demap_noiseless_is_identity(mod):
    bits = torch.randint(
        0, 2, (3, 60 * bits_per_symbol(mod)), generator=torch.Generator().manual_seed(0)
    )
    assert torch.equal(demap_hard(map_bits(bits, mod), mod), bits.to(torch.uint8))


# (modulation, channel, Es/N0 dB, bits): BER 1e-2..1e-1, so >= 1000 errors
CASES = [
    ("bpsk", "awgn", 2.0, 60_000),
    ("qpsk", "awgn", 6.0, 100_000),
    ("16qam", "awgn", 12.0, 200_000),
    ("64qam", "awgn", 18.0, 240_000),
    ("bpsk", "rayleigh", 10.0, 100_000),
    ("qpsk", "rayleigh", 12.0, 100_000),
    ("16qam", "rayleigh", 16.0, 200_000),
    ("64qam", "rayleigh", 22.0, 240_000),
]


@pytest.mark.parametrize("mod, channel, snr_db, num_bits", CASES)
def test_simulated_ber_and_ser_within_4_sigma_of_theory(mod, channel, snr_db, num_bits):
    ch = phy.AWGN() if channel == "awgn" else phy.RayleighFading("fast")
    link = phy.FlatLink(ch, csi="perfect", equalizer="zf")
    c = simulate_uncoded(mod, link, snr_db, num_bits, torch.Generator().manual_seed(7))
    assert c.num_errors >= 1000
    p = ber_theory(mod, snr_db, channel)
    assert abs(c.ber - p) < 4 * math.sqrt(p * (1 - p) / c.num_bits), (c.ber, p)
    ps = ser_theory(mod, snr_db, channel)
    assert abs(c.ser - ps) < 4 * math.sqrt(ps * (1 - ps) / c.num_symbols), (c.ser, ps)


def test_theory_is_vectorised_and_decreasing():
    s = np.arange(-5, 30, 1.0)
    for mod in MODS:
        for ch in ("awgn", "rayleigh"):
            b = ber_theory(mod, s, ch)
            assert b.shape == s.shape and np.all(np.diff(b) < 0) and np.all(b <= 0.5)


def test_theory_bad_input():
    with pytest.raises(KeyError, match="known: .*16qam"):
        ber_theory("8psk", 0.0)
    with pytest.raises(ValueError, match="channel must be one of"):
        ser_theory("qpsk", 0.0, channel="rician")
    with pytest.raises(ValueError, match="bits: last dimension"):
        map_bits(torch.zeros(1, 5), "16qam")
