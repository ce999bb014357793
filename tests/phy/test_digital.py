"""Digital baseline: MCS table, codeword layout, LDPC coding gain, byte-exact round trips."""

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import pytest
import torch
from scipy.special import erfc

import phy
from phy.digital import (
    CRC_BITS,
    MCS_TABLE,
    codeword_layout,
    decode_symbols,
    encode_bytes,
    get_mcs,
    min_num_symbols,
    payload_capacity_bits,
    transmit_bytes,
)


def _payload(num_bytes: int, seed: int = 0) -> bytes:
    return np.random.default_rng(seed).integers(0, 256, num_bytes, dtype=np.uint8).tobytes()


def _bits(b: bytes) -> np.ndarray:
    return np.unpackbits(np.frombuffer(b, dtype=np.uint8))


@dataclass
class _Out:
    x_hat: torch.Tensor
    noise_var: torch.Tensor


def test_mcs_table_is_5g_like():
    rates = {
        name: (m.modulation, m.bits_per_symbol, str(m.code_rate)) for name, m in MCS_TABLE.items()
    }
    assert rates["qpsk-1/3"] == ("qpsk", 2, "1/3")
    assert rates["16qam-3/4"] == ("16qam", 4, "3/4")
    assert rates["64qam-5/6"] == ("64qam", 6, "5/6")
    eff = [m.spectral_efficiency for m in MCS_TABLE.values()]
    assert eff == sorted(eff) and eff[-1] == pytest.approx(5)
    # TS 38.214 Table 5.1.3.1-3 (low spectral efficiency), its QPSK entries below 1/3:
    # MCS 0..10, R x 1024 and the table's spectral efficiency 2 R to four decimals
    low = [(30, 0.0586), (40, 0.0781), (50, 0.0977), (64, 0.1250), (78, 0.1523), (99, 0.1934)]
    low += [(120, 0.2344), (157, 0.3066), (193, 0.3770), (251, 0.4902), (308, 0.6016)]
    for (r, se), m in zip(low, MCS_TABLE.values()):
        assert (m.name, m.modulation) == (f"qpsk-{r}/1024", "qpsk")
        assert round(m.spectral_efficiency, 4) == se
    assert [m.repetition > 1 for m in MCS_TABLE.values()][:10] == [True] * 9 + [False]


def test_unknown_mcs_lists_known_names():
    with pytest.raises(KeyError, match="qpsk-1/2.*64qam-5/6"):
        get_mcs("8psk-1/2")
    with pytest.raises(KeyError, match="unknown MCS .qam-1/2.; known: qpsk-30/1024"):
        payload_capacity_bits(100, "qam-1/2")


def test_layout_by_hand():
    # 1000 QPSK symbols = 2000 coded bits: one codeword, k = 1000, 976 payload bits
    lay = codeword_layout(1000, "qpsk-1/2")
    assert (lay.num_codewords, lay.ldpc_k(0), lay.capacity_bits) == (1, 1000, 1000 - CRC_BITS)
    # 10000 16-QAM symbols = 40000 bits -> ceil(40000/3840) = 11 codewords: 10 of 909
    # symbols (3636 bits, k = 2727) then 1 of 910 symbols (3640 bits, k = 2730)
    lay = codeword_layout(10000, "16qam-3/4")
    assert (lay.num_short, lay.num_long, lay.short_symbols) == (10, 1, 909)
    assert [lay.ldpc_k(0), lay.ldpc_k(10)] == [2727, 2730]
    assert lay.capacity_bits == 10 * (2727 - 24) + (2730 - 24)
    assert payload_capacity_bits(3, "qpsk-1/3") == 0  # 6 coded bits cannot hold a CRC


def test_low_rate_layout_by_hand():
    """Below rate 1/5 a codeword is the 1/5 mother codeword (5 k bits, at most 3840) repeated.
    qpsk-30/1024: the longest codeword is floor(3840 / (5 * 30/1024)) = 26214 bits; 20000
    symbols = 40000 bits -> 2 codewords of 20000 bits, k = floor(20000 * 30/1024) = 585,
    mother 2925 bits, each sent 6.84 times on average."""
    from phy.digital import max_codeword_bits, mother_bits

    assert max_codeword_bits("qpsk-30/1024") == 26214
    assert max_codeword_bits("qpsk-1/3") == 3840  # rates >= 1/5 as before
    lay = codeword_layout(20000, "qpsk-30/1024")
    assert (lay.num_codewords, lay.coded_bits(0), lay.ldpc_k(0)) == (2, 20000, 585)
    assert mother_bits(585, 20000) == 2925 and mother_bits(1000, 2000) == 2000
    assert lay.capacity_bits == 2 * (585 - CRC_BITS)
    # the longest codeword's mother codeword stays within 3840 bits
    big = codeword_layout(26214 // 2, "qpsk-30/1024")
    assert big.num_codewords == 1 and mother_bits(big.ldpc_k(0), 26214) <= 3840


def test_rate_matching_repeats_cyclically_and_combining_adds_the_copies():
    from phy.digital.chain import combine_repeats, rate_match

    c = torch.arange(10.0).reshape(2, 5)
    r = rate_match(c, 12)
    assert r[0].tolist() == [0, 1, 2, 3, 4, 0, 1, 2, 3, 4, 0, 1]
    combined = combine_repeats(r, 5)
    assert combined[1].tolist() == [15.0, 18.0, 14.0, 16.0, 18.0]  # 3, 3, 2, 2, 2 copies
    assert rate_match(c, 5) is c and combine_repeats(c, 5) is c


def _threshold_db(mcs, coded_bits, seed) -> float:
    """50 % codeword-error Es/N0 of ``mcs`` at ``coded_bits`` on AWGN: probit fit to 5 points
    of 200 codewords each around a bisected start."""
    from phy.digital import codeword_errors
    from semcodec.digital.calibration import fit_probit

    link = phy.FlatLink(phy.make_channel("awgn"), csi="perfect", equalizer="zf")
    g = torch.Generator().manual_seed(seed)
    lo, hi = -15.0, 5.0
    for _ in range(6):
        mid = 0.5 * (lo + hi)
        err = codeword_errors(mcs, coded_bits, link, mid, 40, generator=g).float().mean()
        lo, hi = (mid, hi) if err > 0.5 else (lo, mid)
    pts = [0.5 * (lo + hi) + d for d in (-0.5, -0.25, 0.0, 0.25, 0.5)]
    errs = [int(codeword_errors(mcs, coded_bits, link, p, 200, generator=g).sum()) for p in pts]
    return fit_probit(pts, errs, [200] * len(pts))[0]


def test_each_doubling_of_repetition_gains_3_db():
    """The same 200 information bits (CRC included) in 1000, 2000 and 4000 coded bits: the
    rate-1/5 code itself, then its bits sent twice and four times. Chase combining adds the
    copies' LLRs, so r copies at Es/N0 s decode as one at r s: 10 log10 2 = 3.01 dB per
    doubling at equal codeword error rate."""
    from phy.digital import MCS

    t = [
        _threshold_db(MCS(f"qpsk-1/{5 * r}", "qpsk", Fraction(1, 5 * r)), 1000 * r, seed=r)
        for r in (1, 2, 4)
    ]
    assert t[0] - t[1] == pytest.approx(3.01, abs=0.3)
    assert t[1] - t[2] == pytest.approx(3.01, abs=0.3)


def test_lowest_mcs_round_trips_at_minus_10_db():
    """qpsk-30/1024 (about 6.8 copies of a rate-1/5 code) carries 300 bytes at -10 dB Es/N0,
    where uncoded QPSK's bit error rate is 0.33."""
    payload = _payload(300, seed=9)
    res = transmit_bytes(
        payload,
        "qpsk-30/1024",
        phy.FlatLink(phy.AWGN()),
        -10.0,
        generator=torch.Generator().manual_seed(1),
    )
    assert res.ok and res.payload == payload
    assert res.num_symbols == min_num_symbols(300, "qpsk-30/1024")


@pytest.mark.parametrize("mcs", ["qpsk-30/1024", "qpsk-1/3", "16qam-2/3", "64qam-5/6"])
@pytest.mark.parametrize("num_symbols", [60, 997, 5000])
def test_capacity_matches_what_encode_accepts(mcs, num_symbols):
    cap_bytes = payload_capacity_bits(num_symbols, mcs) // 8
    if cap_bytes == 0:  # 60 symbols at 30/1024: 3 information bits, no room for a CRC
        with pytest.raises(ValueError, match="at most 0 bytes"):
            encode_bytes(b"x", mcs, num_symbols=num_symbols)
        return
    x = encode_bytes(_payload(cap_bytes), mcs, num_symbols=num_symbols)
    assert x.shape == (num_symbols,) and x.dtype == torch.complex64
    with pytest.raises(ValueError, match="does not fit num_symbols"):
        encode_bytes(_payload(cap_bytes + 1), mcs, num_symbols=num_symbols)
    # the default length is the fewest symbols that hold the payload
    s = min_num_symbols(cap_bytes, mcs)
    assert s <= num_symbols and payload_capacity_bits(s - 1, mcs) < 8 * cap_bytes
    assert encode_bytes(_payload(cap_bytes), mcs).shape == (s,)


def test_symbols_have_unit_power_even_for_zero_padding():
    x = encode_bytes(b"\x00", "16qam-1/2", num_symbols=20000)  # almost all padding
    # scrambled: mean |x|^2 of 16-QAM within 4 sigma of 1 (var |x|^2 = 0.32)
    assert abs((x.abs() ** 2).mean().item() - 1) < 4 * math.sqrt(0.32 / 20000)


@pytest.mark.parametrize("mcs", list(MCS_TABLE))
def test_round_trip_byte_exact_at_high_snr(mcs):
    payload = _payload(600, seed=1)
    link = phy.FlatLink(phy.AWGN())
    res = transmit_bytes(payload, mcs, link, 30.0, generator=torch.Generator().manual_seed(0))
    assert res.ok and res.payload == payload and res.failed_codewords == []
    assert res.num_symbols == min_num_symbols(600, mcs)
    assert res.extra["mean_iterations"] <= 4  # CRC early stopping works at high SNR


def test_round_trip_over_fast_rayleigh_fading_with_perfect_csi():
    payload = _payload(1500, seed=2)
    link = phy.FlatLink(phy.make_channel("rayleigh_fast"), csi="perfect")
    res = transmit_bytes(
        payload, "qpsk-1/3", link, 10.0, generator=torch.Generator().manual_seed(3)
    )
    assert res.ok and res.payload == payload


def test_low_snr_reports_every_failed_codeword():
    payload = _payload(2000, seed=3)
    res = transmit_bytes(
        payload,
        "64qam-5/6",
        phy.FlatLink(phy.AWGN()),
        5.0,
        generator=torch.Generator().manual_seed(0),
    )
    assert not res.ok and res.payload is None
    assert res.num_codewords == math.ceil(res.num_symbols * 6 / 3840) == 6
    assert res.failed_codewords == list(range(6)) and res.num_payload_codewords == 6
    assert len(res.raw_payload) == 2000 and res.extra["mean_iterations"] == 20


def test_ldpc_coded_ber_below_uncoded_at_same_ebno():
    """QPSK at Eb/N0 = 2.5 dB: uncoded BER = Q(sqrt(2 Eb/N0)) ~ 0.031; rate-1/2 LDPC ~ 0."""
    ebno_db = 2.5
    mcs = get_mcs("qpsk-1/2")
    num_bytes = 6000
    payload = _payload(num_bytes, seed=4)
    g = torch.Generator().manual_seed(5)
    # coded: Es/N0 = Eb/N0 + 10 log10(2 * 1/2) counting each payload bit's share of the rate
    snr_db = phy.ebno_db_to_snr_db(ebno_db, mcs.bits_per_symbol, float(mcs.code_rate))
    res = transmit_bytes(payload, mcs, phy.FlatLink(phy.AWGN()), snr_db, generator=g)
    coded_ber = np.mean(_bits(res.raw_payload) != _bits(payload))
    # uncoded QPSK with the same energy per information bit
    from sionna.phy.mapping import Demapper, Mapper

    n = 8 * num_bytes
    bits = torch.from_numpy(_bits(payload).astype(np.float32))[None]
    x = Mapper("qam", 2)(bits)
    snr_unc = phy.ebno_db_to_snr_db(ebno_db, 2, 1.0)
    out = phy.FlatLink(phy.AWGN())(x.to(torch.complex64), snr_unc, generator=g)
    hard = (Demapper("app", "qam", 2)(out.x_hat, out.noise_var) > 0).float()
    uncoded_ber = (hard != bits).float().mean().item()
    p = 0.5 * erfc(math.sqrt(10 ** (ebno_db / 10)))
    assert abs(uncoded_ber - p) < 4 * math.sqrt(p * (1 - p) / n)
    assert coded_ber < uncoded_ber / 100


def test_decoder_uses_per_symbol_noise_var():
    """40 % of symbols replaced by strong noise: decodable only if noise_var says so."""
    payload = _payload(300, seed=6)
    x = encode_bytes(payload, "qpsk-1/3")
    g = torch.Generator().manual_seed(7)
    bad = torch.rand(x.shape, generator=g) < 0.4
    junk = 3 * torch.randn(x.shape, dtype=torch.complex64, generator=g)
    y = torch.where(bad, junk, x)
    told = torch.where(bad, torch.tensor(1e3), torch.tensor(1e-3))
    assert decode_symbols(y, told, "qpsk-1/3", 300).payload == payload
    assert not decode_symbols(y, 1e-3, "qpsk-1/3", 300).ok


def test_bad_input_one_line_errors():
    x = encode_bytes(b"hello", "qpsk-1/2")
    with pytest.raises(ValueError, match="payload must be bytes"):
        encode_bytes("hello", "qpsk-1/2")
    with pytest.raises(ValueError, match="at least 1 byte"):
        encode_bytes(b"", "qpsk-1/2")
    with pytest.raises(ValueError, match="num_symbols must be an integer >= 1"):
        encode_bytes(b"hello", "qpsk-1/2", num_symbols=0)
    with pytest.raises(ValueError, match="x_hat must be .*complex64, got dtype"):
        decode_symbols(x.real, 0.1, "qpsk-1/2", 5)
    with pytest.raises(ValueError, match=r"noise_var must be .*num_symbols"):
        decode_symbols(x, torch.ones(3), "qpsk-1/2", 5)
    with pytest.raises(ValueError, match="num_bytes=.* exceeds"):
        decode_symbols(x, 0.1, "qpsk-1/2", 10_000)
    with pytest.raises(ValueError, match=r"num_iter must be an integer in \[1, 200\]"):
        decode_symbols(x, 0.1, "qpsk-1/2", 5, num_iter=0)
    with pytest.raises(KeyError, match="unknown MCS") as e:
        decode_symbols(x, 0.1, "nope", 5)
    assert "\n" not in str(e.value)


def test_codeword_errors_waterfall_and_arguments():
    from phy.digital import codeword_errors

    link = phy.FlatLink(phy.make_channel("awgn"), csi="perfect", equalizer="zf")
    g = torch.Generator().manual_seed(0)
    # qpsk-1/2 needs about 1 dB (Es/N0) for 50 % codeword errors at E = 960
    assert not codeword_errors("qpsk-1/2", 960, link, 5.0, 20, generator=g).any()
    assert codeword_errors("qpsk-1/2", 960, link, -3.0, 20, generator=g).all()
    with pytest.raises(ValueError, match="multiple of 4"):
        codeword_errors("16qam-1/2", 962, link, 5.0, 2)
    with pytest.raises(ValueError, match="no room for the CRC"):
        codeword_errors("qpsk-1/3", 60, link, 5.0, 2)
