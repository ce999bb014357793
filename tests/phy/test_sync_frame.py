"""Synchronisation and over-the-air frames: timing, CFO, SCO, multipath, several frames."""

import math

import numpy as np
import pytest
import torch
from scipy.signal import resample

import phy
from phy import sync

CFG = phy.FrameConfig()
TAPS = np.array([1, 0, 0.5j, 0, 0, 0.3, 0, 0, 0, -0.2])  # 10 samples: within cp - backoff = 12
MILD_TAPS = np.array([1, 0, 0, 0.4j, 0, 0.2])  # |H| >= 0.4 on every carrier


def _qpsk(n, seed=0):
    b = np.random.default_rng(seed).integers(0, 2, size=(n, 2))
    return (((1 - 2 * b[:, 0]) + 1j * (1 - 2 * b[:, 1])) / math.sqrt(2)).astype(np.complex64)


def resampled_ppm(num_samples, ppm):
    """The clock offset ``impair`` really applies: its output length is a whole number."""
    n = num_samples + 64
    return (round(n * (1 + ppm * 1e-6)) / n - 1) * 1e6


def impair(iq, snr_db, cfo=0.0, sco_ppm=0.0, taps=None, lead=0, tail=0, seed=1):
    """Transmitter -> air -> receiver: sampling-clock offset (band-limited resampling, positive
    = the receiver samples faster), multipath, unknown start, CFO (subcarriers), AWGN at
    ``snr_db`` relative to the frame's mean power per sample."""
    rng = np.random.default_rng(seed)
    s = iq.astype(np.complex128)
    p = np.mean(np.abs(s) ** 2)
    if sco_ppm:
        s = np.r_[s, np.zeros(64)]
        s = resample(s, int(round(len(s) * (1 + sco_ppm * 1e-6))))
    if taps is not None:
        s = np.convolve(s, taps)[: len(s)]
    s = np.r_[np.zeros(lead), s, np.zeros(tail)]
    s = s * np.exp(2j * np.pi * cfo * np.arange(len(s)) / CFG.fft_size)
    nv = p * 10 ** (-snr_db / 10)
    s = s + math.sqrt(nv / 2) * (rng.standard_normal(len(s)) + 1j * rng.standard_normal(len(s)))
    return s.astype(np.complex64)


def test_frame_layout_power_and_sync_repetitions():
    x = _qpsk(1000)
    t = phy.build_frame(x, CFG)
    assert t.dtype == np.complex64 and t.shape == (CFG.num_samples(1000),)
    # sync (2048) + two training symbols + ceil(1000 / 38) data symbols (52 used - 14 pilots)
    assert CFG.num_samples(1000) == 2048 + 2 * 80 + math.ceil(1000 / 38) * 80
    assert np.sqrt(np.mean(np.abs(t) ** 2)) == pytest.approx(CFG.rms_amplitude, rel=0.03)
    assert np.abs(t).max() <= 1.0
    base, cover = phy.frame.sync_sequence(CFG)
    segs = t[:2048].reshape(128, 16)
    np.testing.assert_allclose(segs, np.outer(cover, base) * CFG.rms_amplitude, atol=1e-6)
    # the base sequence lives on used carriers only: nothing on DC or in the guards
    spec = np.abs(np.fft.fft(base)) ** 2
    assert spec[0] < 1e-20 and np.mean(np.abs(base) ** 2) == pytest.approx(1.0)
    lts = t[2048 : 2048 + 80]
    np.testing.assert_allclose(lts[:16], lts[-16:], atol=1e-7)  # cyclic prefix
    np.testing.assert_allclose(t[2048:2128], t[2128:2208], atol=1e-7)  # two equal symbols


def test_correct_cfo_removes_a_rotation():
    t = phy.build_frame(_qpsk(100), CFG)
    r = sync.correct_cfo(t, -0.3, 64)  # adds +0.3 carriers
    ref = t * np.exp(2j * np.pi * 0.3 * np.arange(t.size) / 64)
    np.testing.assert_allclose(r, ref, atol=1e-5)
    np.testing.assert_allclose(sync.correct_cfo(r, 0.3, 64), t, atol=1e-5)


@pytest.mark.parametrize("cfo", [0.0, 1.3, -1.9])
def test_timing_found_exactly_at_high_snr(cfo):
    x = _qpsk(500)
    r = impair(phy.build_frame(x, CFG), 30.0, cfo=cfo, lead=1234, tail=200)
    res = phy.receive_frame(r, CFG, 500)
    assert res.detected and res.start_index == 1234
    assert abs(res.cfo_subcarriers - cfo) < 0.005
    assert res.cfo_hz == pytest.approx(res.cfo_subcarriers * CFG.sample_rate_hz / 64)


@pytest.mark.parametrize("cfo, seed", [(6.4, 1), (-3.5, 2), (2.2, 3)])
def test_cfo_of_several_subcarriers_with_multipath_and_unknown_start(cfo, seed):
    """Stated bound: |CFO error| < 0.01 subcarrier at 15 dB, first path found within 1 sample.
    Segments of 4 samples widen the CFO range to +-8 carriers (at a cost in sensitivity)."""
    cfg = phy.FrameConfig(sync_segment_length=4, max_cfo_subcarriers=8.0)
    x = _qpsk(2000, seed)
    lead = int(np.random.default_rng(seed).integers(100, 5000))
    r = impair(phy.build_frame(x, cfg), 15.0, cfo=cfo, taps=TAPS, lead=lead, tail=300, seed=seed)
    res = phy.receive_frame(r, cfg, 2000)
    assert res.detected
    assert abs(res.cfo_subcarriers - cfo) < 0.01
    assert abs(res.start_index - lead) <= 1
    err = (res.symbols.numpy() - x).__abs__() ** 2
    assert err.mean() == pytest.approx(res.noise_var.mean().item(), rel=0.35)
    assert res.snr_db_estimate > 12


def test_payload_is_error_free_after_cfo_multipath_at_25_db():
    x = _qpsk(3000, 4)
    r = impair(phy.build_frame(x, CFG), 25.0, cfo=1.1, taps=MILD_TAPS, lead=777, tail=100, seed=4)
    res = phy.receive_frame(r, CFG, 3000, equalizer="zf")
    assert res.symbols.dtype == torch.complex64 and res.noise_var.dtype == torch.float32
    idx = phy.hard_decision(res.symbols, "qpsk")
    assert torch.equal(idx, phy.hard_decision(torch.from_numpy(x), "qpsk"))


@pytest.mark.parametrize("ppm", [100.0, -150.0])
def test_sampling_clock_drift_is_tracked(ppm):
    """12000 symbols = 316 OFDM symbols = 25k samples: 100 ppm drifts 2.5 samples over the frame."""
    x = _qpsk(12000, 5)
    r = impair(phy.build_frame(x, CFG), 30.0, cfo=1.3, sco_ppm=ppm, lead=300, tail=300, seed=5)
    res = phy.receive_frame(r, CFG, 12000)
    assert res.detected and abs(res.sco_ppm - resampled_ppm(CFG.num_samples(12000), ppm)) < 5
    err = np.abs(res.symbols.numpy() - x) ** 2
    assert err.mean() < 0.01  # ~20 dB after tracking; without it the frame end is lost
    first, last = err[:2000].mean(), err[-2000:].mean()
    assert last < 3 * first + 0.003


def test_find_frames_in_a_capture_with_several():
    x = _qpsk(800, 6)
    t = phy.build_frame(x, CFG)
    parts, starts, pos = [], [], 0
    for i, gap in enumerate([333, 1000, 2500]):
        seg = impair(t, 20.0, cfo=1.7, lead=gap, tail=0, seed=10 + i)
        starts.append(pos + gap)
        parts.append(seg)
        pos += len(seg)
    dc = 0.05 + 0.02j  # an SDR's DC offset: silence must not look like a preamble
    r = np.concatenate(parts + [np.zeros(3000, np.complex64)]) + dc
    assert phy.find_frames(r, CFG) == starts
    second = phy.receive_frame(r, CFG, 800, search_from=starts[0] + 100)
    assert second.start_index == starts[1]


def test_detection_at_minus_10_db_with_multipath():
    """Stated: every frame found at -10 dB (per sample) over TAPS, the start within 2 samples
    (inside the window start's backoff of 4), the CFO within 0.02 carriers."""
    t = phy.build_frame(_qpsk(500), CFG)
    for seed in range(8):
        lead = 400 + 37 * seed
        res = phy.receive_frame(
            impair(t, -10.0, cfo=-1.6, taps=TAPS, lead=lead, tail=200, seed=seed), CFG, 500
        )
        assert res.detected and abs(res.start_index - lead) <= 2
        assert abs(res.cfo_subcarriers + 1.6) < 0.02


def test_noise_only_and_truncated_frames_are_not_detected():
    rng = np.random.default_rng(0)
    noise = (0.1 * (rng.standard_normal(50_000) + 1j * rng.standard_normal(50_000))).astype(
        np.complex64
    )
    assert phy.find_frames(noise, CFG) == []
    res = phy.receive_frame(noise, CFG, 100)
    assert not res.detected and res.start_index == -1 and torch.isinf(res.noise_var).all()
    t = phy.build_frame(_qpsk(1000), CFG)
    cut = impair(t, 30.0, lead=100)[: 100 + len(t) - 200]
    assert not phy.receive_frame(cut, CFG, 1000).detected


def test_frame_bad_input():
    with pytest.raises(ValueError, match="iq must be a 1-D complex64"):
        phy.receive_frame(np.zeros(1000, np.float32), CFG, 10)
    with pytest.raises(ValueError, match="iq must be a 1-D complex64"):
        phy.find_frames(np.zeros((2, 1000), np.complex64), CFG)
    with pytest.raises(ValueError, match="num_symbols must be"):
        phy.receive_frame(np.zeros(1000, np.complex64), CFG, 0)
    with pytest.raises(ValueError, match="symbols must be a 1-D complex64"):
        phy.build_frame(np.ones(10), CFG)
    with pytest.raises(ValueError, match="fft_size must be a multiple of 4"):
        phy.FrameConfig(fft_size=50)
    with pytest.raises(ValueError, match="cp_length must be"):
        phy.FrameConfig(cp_length=1)
    with pytest.raises(ValueError, match="equalizer must be one of"):
        phy.receive_frame(np.zeros(1000, np.complex64), CFG, 10, equalizer="ml")
