"""The receiver chain against its frozen reference (``benchmarks.reference_receiver``) on
captures generated from seeds: the same frames at the same offsets, the same CFOs to rounding,
the same decoded bits."""

import math

import numpy as np
import pytest
from scipy.signal import resample

import phy
from benchmarks.reference_receiver import detection as detection_reference
from benchmarks.reference_receiver import receiver as receiver_reference
from phy import detection

CFG = phy.FrameConfig()
FAST = phy.FrameConfig(sample_rate_hz=20e6)  # the benchmark's configuration
TAPS = np.array([1, 0, 0.4j, 0, 0.2])
NUM_SYMBOLS = 1500


def _qpsk(n, rng):
    b = rng.integers(0, 2, size=(n, 2))
    return (((1 - 2 * b[:, 0]) + 1j * (1 - 2 * b[:, 1])) / math.sqrt(2)).astype(np.complex64)


def _capture(seed, size, starts, snr_db, cfos, cfg=CFG, num_symbols=NUM_SYMBOLS):
    """[size] complex64: frames (multipath, CFO ``cfos[i]`` carriers) at ``starts`` (cut where
    they run past the end) in unit-power noise at ``snr_db`` per sample; a DC offset."""
    rng = np.random.default_rng(seed)
    r = (rng.standard_normal(size) + 1j * rng.standard_normal(size)) / math.sqrt(2)
    amp = 10 ** (snr_db / 20) / cfg.rms_amplitude
    for start, cfo in zip(starts, cfos):
        t = np.convolve(phy.build_frame(_qpsk(num_symbols, rng), cfg), TAPS)[: -TAPS.size + 1]
        t = t * np.exp(2j * np.pi * cfo * np.arange(t.size) / cfg.fft_size)
        end = min(size, start + t.size)
        r[start:end] += amp * t[: end - start]
    return (r + 0.05 - 0.03j).astype(np.complex64)


LEN = CFG.num_samples(NUM_SYMBOLS)
EDGE = 1 << 18  # the search's chunk edge
CASES = {
    "one frame, 20 dB": (1, 40_000, [3001], 20.0, [0.157], FAST),
    "one frame, -10 dB, CFO 1.3": (2, 40_000, [5000], -10.0, [1.3], CFG),
    "three frames, 0 dB, CFOs": (
        3,
        5 * LEN,
        [700, LEN + 1500, 2 * LEN + 9000],
        0.0,
        [-0.8, 0.4, 1.7],
        CFG,
    ),
    "noise only": (4, EDGE + 40_000, [], 0.0, [], CFG),
    "preamble across the chunk edge, frame cut at the end": (
        5,
        EDGE + 2 * LEN - 1000,
        [EDGE - 1000, EDGE + LEN - 300],
        5.0,
        [0.3, -0.2],
        CFG,
    ),
    "frames across comb blocks, 10 dB": (
        6,
        7 * LEN,
        [14_368 - 1500, 2 * 14_368 - 993],
        10.0,
        [0.05, -1.1],
        CFG,
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_search_finds_the_reference_frames(case):
    seed, size, starts, snr_db, cfos, cfg = CASES[case]
    r = _capture(seed, size, starts, snr_db, cfos, cfg)
    x = r - r.mean()
    new = detection.find_preambles(x, cfg)
    ref = detection_reference.find_preambles(x, cfg)
    assert [d.start for d in new] == [d.start for d in ref]
    np.testing.assert_allclose([d.cfo for d in new], [d.cfo for d in ref], atol=1e-4)
    np.testing.assert_allclose([d.metric for d in new], [d.metric for d in ref], rtol=1e-4)
    assert phy.find_frames(r, cfg) == receiver_reference.find_frames(r, cfg)
    assert len(new) == len(starts)  # every frame (a cut one too), nothing else


def _bits(res):
    s = res.symbols.numpy()
    return np.stack([s.real > 0, s.imag > 0], axis=-1)


@pytest.mark.parametrize("case", [c for c in CASES if CASES[c][2]])
@pytest.mark.parametrize("equalizer", ["zf", "mmse"])
def test_receiver_decodes_the_reference_bits(case, equalizer):
    seed, size, starts, snr_db, cfos, cfg = CASES[case]
    r = _capture(seed, size, starts, snr_db, cfos, cfg)
    frm = 0
    while True:
        new = phy.receive_frame(r, cfg, NUM_SYMBOLS, search_from=frm, equalizer=equalizer)
        ref = receiver_reference.receive_frame(
            r, cfg, NUM_SYMBOLS, search_from=frm, equalizer=equalizer
        )
        assert (new.detected, new.start_index) == (ref.detected, ref.start_index)
        if not new.detected:
            break
        assert np.array_equal(_bits(new), _bits(ref))
        np.testing.assert_allclose(new.symbols.numpy(), ref.symbols.numpy(), atol=1e-3)
        assert new.cfo_subcarriers == pytest.approx(ref.cfo_subcarriers, abs=1e-4)
        assert new.effective_snr_db == pytest.approx(ref.effective_snr_db, abs=1e-3)
        frm = new.start_index + 1
        if frm >= r.size:
            break


@pytest.mark.parametrize("locked", [False, True])
def test_receiver_with_clock_drift_decodes_the_reference_bits(locked):
    """A sampling-clock offset (the window follows the drift, estimated from the pilots or
    from the CFO when both radios share a crystal) takes the receiver's other paths."""
    cfg = phy.FrameConfig(carrier_freq_hz=2.4e9) if locked else CFG
    rng = np.random.default_rng(8)
    t = phy.build_frame(_qpsk(4000, rng), cfg).astype(np.complex128)
    t = resample(t, round(t.size * (1 + 80e-6)))  # the receiver samples 80 ppm fast
    s = np.r_[np.zeros(900), t, np.zeros(700)] * (10 ** (15 / 20) / cfg.rms_amplitude)
    s = s * np.exp(2j * np.pi * 0.6 * np.arange(s.size) / cfg.fft_size)
    s += (rng.standard_normal(s.size) + 1j * rng.standard_normal(s.size)) / math.sqrt(2)
    r = s.astype(np.complex64)
    new = phy.receive_frame(r, cfg, 4000)
    ref = receiver_reference.receive_frame(r, cfg, 4000)
    assert new.detected and (new.start_index, new.detected) == (ref.start_index, ref.detected)
    assert abs(new.sco_ppm) > 5  # a drift was followed (per-row windows and ramps)
    assert new.sco_ppm == pytest.approx(ref.sco_ppm, abs=1e-3)
    assert np.array_equal(_bits(new), _bits(ref))
    np.testing.assert_allclose(new.symbols.numpy(), ref.symbols.numpy(), atol=1e-3)


@pytest.mark.parametrize("case", [c for c in CASES if len(CASES[c][2]) > 1])
def test_receive_frames_gives_every_frame_the_reference_gives(case):
    """One search for a block of frames (the stream's path): the frames, offsets and bits
    that the reference's receive_frame gives when called again after each frame found."""
    seed, size, starts, snr_db, cfos, cfg = CASES[case]
    r = _capture(seed, size, starts, snr_db, cfos, cfg)
    batch = phy.receive_frames(r, cfg, NUM_SYMBOLS, equalizer="mmse")
    ref, frm = [], 0
    while frm < r.size:
        res = receiver_reference.receive_frame(r, cfg, NUM_SYMBOLS, frm, equalizer="mmse")
        if not res.detected:
            break
        ref.append(res)
        frm = res.start_index + 1
    assert [b.start_index for b in batch] == [f.start_index for f in ref]
    assert all(b.detected for b in batch) and len(batch) >= 1
    for b, f in zip(batch, ref):
        assert np.array_equal(_bits(b), _bits(f))
        np.testing.assert_allclose(b.symbols.numpy(), f.symbols.numpy(), atol=1e-3)
        assert b.cfo_subcarriers == pytest.approx(f.cfo_subcarriers, abs=1e-4)
