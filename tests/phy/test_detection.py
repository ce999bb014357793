"""The low-SNR receiver against theory: detector statistics, CFO error, channel-estimate MSE,
interleaver, timing drift; and no false detection in 10^7 samples of noise."""

import math

import numpy as np
import pytest

import phy
from phy import detection, estimation
from phy.frame import interleaver, sync_sequence

CFG = phy.FrameConfig()
N = CFG.sync_length


def _noise(n, seed, var=1.0):
    rng = np.random.default_rng(seed)
    return (np.sqrt(var / 2) * (rng.standard_normal(n) + 1j * rng.standard_normal(n))).astype(
        np.complex64
    )


def _metric_at(r, lags, f_bin=0):
    """Q at the given lags for the CFO hypothesis of bin ``f_bin`` (exact energy windows)."""
    base, cover = sync_sequence(CFG)
    c = detection.segment_correlation(r, base)
    cs = np.concatenate([[0.0], np.cumsum(np.abs(r.astype(np.complex128)) ** 2)])
    energy = cs[lags + N] - cs[lags]
    q, _ = detection.coherent_metric(c, energy, lags, cover, CFG.sync_segment_length)
    return q[:, f_bin]


def test_coherent_metric_in_noise_is_beta_1_n_minus_1():
    """Q = |<r, q>|^2 / (|q|^2 |r|^2) is Beta(1, N - 1): P(Q > t) = (1 - t)^(N - 1), whatever
    the noise power. 4e4 lags (neighbours nearly independent) at Pfa 1e-2 and 2e-3."""
    r = _noise(40_000 + N, 1, var=7.3)
    lags = np.arange(40_000)
    q = _metric_at(r, lags)
    assert q.mean() == pytest.approx(1 / N, rel=0.03)  # Beta(1, N - 1) mean
    for pfa in (1e-2, 2e-3):
        t = detection.threshold_for_pfa(pfa, N)
        assert detection.pfa_coherent(t, N) == pytest.approx(pfa)
        k = int(np.sum(q > t))
        assert abs(k - pfa * lags.size) < 4 * math.sqrt(pfa * lags.size) * 1.3


@pytest.mark.parametrize("snr_db", [-19.0, -18.0])
def test_coherent_metric_detection_probability_is_the_noncentral_f(snr_db):
    """A preamble at per-sample SNR rho, at its lag and CFO: Pd = P(Q > t) from the
    noncentral F with noncentrality 2 N rho, within 4 binomial sigmas over 2000 trials."""
    base, cover = sync_sequence(CFG)
    p = (cover[:, None] * base[None, :]).reshape(-1).astype(np.complex64)
    trials = 2000
    rho = 10 ** (snr_db / 10)
    r = (np.tile(p, trials) * math.sqrt(rho) + _noise(trials * N, 2)).astype(np.complex64)
    r = np.r_[r, np.zeros(N, np.complex64)]
    q = _metric_at(r, np.arange(trials) * N)
    t = CFG.detection_threshold
    pd = detection.pd_coherent(t, N, rho)
    assert 0.05 < pd < 0.95  # the interesting range
    got = float(np.mean(q > t))
    assert abs(got - pd) < 4 * math.sqrt(pd * (1 - pd) / trials)


def test_default_threshold_pd_at_minus_10_db_and_pfa():
    """The documented operating point: Pd > 0.9999 at -10 dB even with 3 dB of CFO,
    multipath and ADC-clipping losses; Pfa per hypothesis below 1e-13."""
    t = CFG.detection_threshold
    assert detection.pd_coherent(t, N, 10 ** (-13 / 10)) > 0.9999
    assert detection.pfa_coherent(t, N) < 1e-13


def test_no_false_detection_in_ten_million_noise_samples():
    """10^7 samples of complex noise (plus a DC offset), searched in one vectorised pass."""
    r = _noise(10_000_000, 3, var=0.01) + np.complex64(0.02 - 0.01j)
    assert phy.find_frames(r, CFG) == []


def test_cfo_error_at_minus_10_db_matches_the_two_halves_estimator():
    """Fine CFO from the phase between the preamble's halves: var(f) = 2 / (pi^2 rho N^3)
    cycles^2/sample^2 (each half sums N/2 samples at SNR rho). RMS error over 40 frames at
    -10 dB, flat channel, CFO 1.3 carriers, within [0.6, 1.5] of it (chi^2, 40 dof)."""
    x = np.exp(2j * np.pi * np.random.default_rng(0).random(200)).astype(np.complex64)
    t = phy.build_frame(x, CFG)
    p = np.mean(np.abs(t) ** 2)
    rho = 10 ** (-10 / 10)
    errs = []
    for seed in range(40):
        s = np.r_[np.zeros(700), t, np.zeros(300)].astype(np.complex128)
        s *= np.exp(2j * np.pi * 1.3 * np.arange(s.size) / 64)
        r = (s + _noise(s.size, 100 + seed, var=p / rho)).astype(np.complex64)
        dets = detection.find_preambles(r - r.mean(), CFG)
        assert len(dets) == 1 and abs(dets[0].start - 700) <= 2
        errs.append((dets[0].cfo - 1.3) / 64)  # cycles per sample
    theory = math.sqrt(2 / (math.pi**2 * rho * N**3))
    rms = math.sqrt(np.mean(np.square(errs)))
    assert 0.6 * theory < rms < 1.5 * theory


def test_channel_estimate_mse_ls_and_smoothed_against_theory():
    """Per-carrier LS from `counts` observations has MSE sigma^2 / counts; the delay-domain
    WLS fit has MSE sigma^2 [F (F^H W F)^-1 F^H]_kk, mean sigma^2 T / (K counts) for equal
    counts. 4000 trials, 52 carriers, 14 taps, a channel inside the window."""
    rng = np.random.default_rng(5)
    used = CFG.data_grid(1).used_subcarriers
    basis = estimation.delay_basis(used, 64, np.arange(-4, 10))
    counts = np.full(used.size, 3.0)
    counts[::4] = 40.0  # pilot carriers
    p_mat, factor = estimation.channel_smoother(counts, basis)
    sigma2, trials = 0.5, 4000
    taps = (rng.standard_normal((trials, 14)) + 1j * rng.standard_normal((trials, 14))) / 4
    h = taps @ basis.T  # [trials, num_used]
    noise = rng.standard_normal((trials, used.size)) + 1j * rng.standard_normal((trials, used.size))
    sums = h * counts + noise * np.sqrt(sigma2 * counts / 2)
    ls = sums / counts
    smoothed = sums @ p_mat.T
    mse_ls = np.mean(np.abs(ls - h) ** 2, axis=0)
    mse_sm = np.mean(np.abs(smoothed - h) ** 2, axis=0)
    np.testing.assert_allclose(mse_ls, sigma2 / counts, rtol=0.1)
    np.testing.assert_allclose(mse_sm, sigma2 * factor, rtol=0.1)
    assert mse_sm.mean() < 0.5 * mse_ls.mean()
    equal = estimation.channel_smoother(np.full(used.size, 3.0), basis)[1]
    assert equal.mean() == pytest.approx(14 / (used.size * 3.0))


def test_interleaver_round_trip_and_spread():
    perm = interleaver(2204)
    assert np.array_equal(np.sort(perm), np.arange(2204))
    x = np.arange(2204)
    assert np.array_equal(x[perm][np.argsort(perm)], x)
    # payload neighbours land on different OFDM symbols (38 data elements each) and carriers
    where = np.argsort(perm)  # resource element of payload symbol i
    row = where // 38
    assert np.mean(row[1:] != row[:-1]) > 0.95
    # end to end: a clean frame comes back exactly, in order
    sym = np.exp(2j * np.pi * np.random.default_rng(1).random(1000)).astype(np.complex64)
    t = phy.build_frame(sym, CFG)
    r = np.r_[np.zeros(500, np.complex64), t, np.zeros(500, np.complex64)]
    res = phy.receive_frame(r + _noise(r.size, 9, var=1e-8), CFG, 1000)
    np.testing.assert_allclose(res.symbols.numpy(), sym, atol=2e-3)


def test_common_phase_line_and_drift_are_recovered():
    rows = 120
    rng = np.random.default_rng(4)
    a = 10 * np.exp(1j * (0.3 + 0.021 * np.arange(rows))) + rng.standard_normal(rows)
    phi, slope = estimation.track_phase(a, snr_row=100.0 / 2)
    assert slope == pytest.approx(0.021, abs=5e-4)
    # a drift of 50 ppm over pilots 4 carriers apart, high SNR
    times = 80.0 * np.arange(rows)
    pk = np.arange(-24, 25, 4)
    tau = 50e-6 * times
    z = 3 * np.exp(-2j * np.pi * np.outer(tau, pk) / 64)
    d = estimation.track_delay(z, np.arange(pk.size - 1), 4, times, 64, snr_row=1e4)
    assert d == pytest.approx(50e-6, rel=0.01)
    noisy = z + 3 * (rng.standard_normal(z.shape) + 1j * rng.standard_normal(z.shape))
    assert estimation.track_delay(noisy * 0.05, np.arange(12), 4, times, 64, 0.01) == 0.0


def test_locked_clocks_take_the_drift_from_the_cfo():
    """carrier_freq_hz set: sco_ppm == -cfo_hz / carrier_freq_hz, exact at -10 dB."""
    cfg = phy.FrameConfig(carrier_freq_hz=2.45e9)
    x = np.exp(2j * np.pi * np.random.default_rng(2).random(600)).astype(np.complex64)
    t = phy.build_frame(x, cfg)
    s = np.r_[np.zeros(400), t, np.zeros(200)] * np.exp(
        2j * np.pi * -0.784 * np.arange(t.size + 600) / 64
    )
    r = (s + _noise(s.size, 6, var=np.mean(np.abs(t) ** 2) * 10)).astype(np.complex64)
    res = phy.receive_frame(r, cfg, 600)
    assert res.detected and res.sco_ppm == pytest.approx(-res.cfo_hz / 2.45e9 * 1e6, abs=0.1)
    assert abs(res.sco_ppm - 20.0) < 0.5  # -0.784 carriers at 4 MS/s = -49 kHz = 20 ppm


def test_frame_config_validation_names_fields():
    with pytest.raises(ValueError, match="sync_segment_length"):
        phy.FrameConfig(sync_segment_length=12)
    with pytest.raises(ValueError, match="sync_length"):
        phy.FrameConfig(sync_length=1000)
    with pytest.raises(ValueError, match="max_cfo_subcarriers"):
        phy.FrameConfig(max_cfo_subcarriers=3.0)
    with pytest.raises(ValueError, match="carrier_freq_hz"):
        phy.FrameConfig(carrier_freq_hz=-1.0)
