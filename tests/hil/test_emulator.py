"""The emulated air: exact passthrough, delay, carrier and sampling-clock offsets from ppm,
SNR, multipath, gains, I/Q imbalance, determinism. Closed forms, not smoke."""

import threading

import numpy as np
import pytest

from hil import AirChannel, Emulator, HackRF, loopback_pair
from hil.emulation import fractional_resample, iq_imbalance
from hil.iq import to_int8_iq

FS = 2e6


def burst(n, power_dbfs=-15.0, seed=0):
    rng = np.random.default_rng(seed)
    x = (rng.standard_normal(n) + 1j * rng.standard_normal(n)) * np.sqrt(
        10 ** (power_dbfs / 10) / 2
    )
    return np.clip(x.real, -1, 1) + 1j * np.clip(x.imag, -1, 1)


def send_and_capture(
    x, num_rx, channel, ppm=(0.0, 0.0), seed=0, freqs=(915e6, 915e6), rx_gains=(16, 24)
):
    tx, rx, _ = loopback_pair(channel, ppm=ppm, seed=seed, rx_chunk_bytes=16384)
    with tx, rx:
        for d, f in zip((tx, rx), freqs):
            d.sample_rate_hz = FS
            d.center_freq_hz = f
        rx.lna_gain_db, rx.vga_gain_db = rx_gains
        tx.tx(x)  # wait_for_bursts=1: the receiver sees the burst from its sample 0 on
        return rx.rx(num_rx)[0]


def q(x):
    return to_int8_iq(x).astype(np.float32).view(np.complex64) / 128


def test_ideal_air_is_an_exact_int8_passthrough():
    x = burst(5000)
    y = send_and_capture(x, 6000, AirChannel(snr_db=100))
    assert np.array_equal(y[:5000], q(x))
    assert np.all(y[5000:] == 0)


def test_integer_delay_shifts_exactly():
    x = burst(3000)
    y = send_and_capture(x, 4000, AirChannel(snr_db=100, delay_s=25 / FS))
    assert np.all(y[:25] == 0) and np.array_equal(y[25:3025], q(x))


def test_snr_matches_the_setting():
    x = burst(100_000, power_dbfs=-15)
    y = send_and_capture(x, 100_000, AirChannel(snr_db=10, reference_power_dbfs=-15))
    err = y - q(x)
    snr = 10 * np.log10(np.mean(np.abs(q(x)) ** 2) / np.mean(np.abs(err) ** 2))
    assert snr == pytest.approx(10.0, abs=0.2)


def test_rx_gain_scales_signal_and_noise():
    x = burst(4000, power_dbfs=-20)
    y = send_and_capture(
        x, 4000, AirChannel(snr_db=100), rx_gains=(16, 30)
    )  # +6 dB over the reference 40
    assert np.max(np.abs(y - 10 ** (6 / 20) * q(x))) < 1.5 / 128


def test_multipath_is_the_normalised_fir():
    x = burst(4000)
    ch = AirChannel(snr_db=100, multipath=((3, 0.5j), (7, -0.25)))
    y = send_and_capture(x, 4000, ch)
    h = np.array([1, 0, 0, 0.5j, 0, 0, 0, -0.25])
    h = h / np.linalg.norm(h)
    assert np.allclose(ch.taps, h)
    expected = np.convolve(q(x), h)[:4000]
    assert np.max(np.abs(y - expected)) < 1.0 / 128


def test_carrier_offset_from_ppm():
    n = 20_000
    x = np.full(n, 0.25 + 0j)
    y = send_and_capture(x, n, AirChannel(snr_db=60), ppm=(0.0, 20.0), freqs=(2.45e9, 2.45e9))
    fs_rx = FS * (1 + 20e-6)
    seg = y[100 : n - 100]
    df = np.angle(np.sum(seg[1:] * np.conj(seg[:-1]))) * fs_rx / (2 * np.pi)
    assert df == pytest.approx(2.45e9 * (0 - 20e-6), abs=2.0)  # -49 kHz: TX LO below RX LO


def test_sampling_clock_offset_stretches_time():
    """100 ppm faster RX clock: two bursts 200000 TX samples apart arrive 200020 apart."""
    rng = np.random.default_rng(7)
    probe = np.exp(2j * np.pi * rng.integers(0, 4, 256) / 4) * 0.2
    x = np.zeros(200_000 + 256, complex)
    x[:256], x[200_000:] = probe, probe
    f = 100e6
    y = send_and_capture(x, 200_400, AirChannel(snr_db=40), ppm=(0.0, 100.0), freqs=(f, f))
    df = f * (0 - 100e-6)
    fs_rx = FS * (1 + 100e-6)
    y = y * np.exp(-2j * np.pi * df * np.arange(len(y)) / fs_rx)

    def peak(lo, hi):
        c = np.abs(np.correlate(y[lo:hi], probe, "valid"))
        k = int(np.argmax(c))
        a, b, d = c[k - 1], c[k], c[k + 1]
        return lo + k + 0.5 * (a - d) / (a - 2 * b + d)

    assert peak(200_000, 200_400) - peak(0, 400) == pytest.approx(200_020, abs=0.3)


def test_out_of_band_transmitter_is_not_received():
    x = burst(4000, power_dbfs=-6)
    y = send_and_capture(
        x, 4000, AirChannel(snr_db=30), freqs=(915e6, 920e6)
    )  # 5 MHz away at 2 MS/s
    assert np.mean(np.abs(y) ** 2) < 10 ** (-30 / 10)  # noise only (-45 dBFS)


def test_iq_imbalance_closed_form():
    rng = np.random.default_rng(0)
    y = rng.standard_normal(100) + 1j * rng.standard_normal(100)
    g, phi = 10 ** (1 / 20), np.radians(5)
    z = iq_imbalance(y, 1.0, 5.0)
    assert np.allclose(z.real, y.real, atol=1e-6)
    assert np.allclose(z.imag, g * (y.imag * np.cos(phi) - y.real * np.sin(phi)), atol=1e-5)
    assert np.array_equal(iq_imbalance(y.astype(np.complex64), 0, 0), y.astype(np.complex64))


def test_fractional_resample_of_a_bandlimited_signal():
    n = np.arange(4000)
    f = np.array([0.05, 0.17, 0.31, -0.44])  # up to 0.44 fs: OFDM edge carriers
    x = np.sum(np.exp(2j * np.pi * f[:, None] * n[None, :]), axis=0)
    pos = np.arange(100, 3900) + 0.37
    truth = np.sum(np.exp(2j * np.pi * f[:, None] * pos[None, :]), axis=0)
    err = fractional_resample(x, pos) - truth
    assert 10 * np.log10(np.mean(np.abs(err) ** 2) / 4) < -55
    assert np.array_equal(
        fractional_resample(x, np.arange(10, 20.0)), x[10:20].astype(np.complex64)
    )


def _threaded_usb_capture(seed):
    """TX and RX on their own threads over pyusb: still bit-identical for a seed."""
    emu = Emulator(
        AirChannel(snr_db=15, delay_s=3.3e-6, multipath=((2, 0.4),)),
        ppm=(-10.0, 10.0),
        seed=seed,
        wait_for_bursts=1,
    )
    tx = HackRF.open(emu.serials[0], backend=emu.backend)
    rx = HackRF.open(emu.serials[1], backend=emu.backend, rx_chunk_bytes=16384)
    for d in (tx, rx):
        d.sample_rate_hz = FS
    out = {}
    t = threading.Thread(target=lambda: out.setdefault("y", rx.rx(30_000)))
    t.start()
    tx.tx(burst(20_000))
    t.join()
    tx.close()
    rx.close()
    return out["y"]


def test_deterministic_given_a_seed_whatever_the_threads_do():
    a, b, c = _threaded_usb_capture(1), _threaded_usb_capture(1), _threaded_usb_capture(2)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_channel_validation_names_fields():
    with pytest.raises(ValueError, match="snr_db must be in"):
        AirChannel(snr_db=200)
    with pytest.raises(ValueError, match="multipath delays must be integers"):
        AirChannel(multipath=((0.5, 1),))


def test_from_taps_keeps_a_fading_realisation():
    """A drawn channel (tap gains as given, not normalised) fades the received power."""
    taps = np.array([0.1j, 0, 0.05 - 0.02j])
    ch = AirChannel.from_taps(taps, snr_db=100)
    assert ch.multipath == ((2, 0.05 - 0.02j),) and ch.direct_gain == 0.1j
    x = burst(4000, power_dbfs=-3)
    y = send_and_capture(x, 4000, ch)
    expected = np.convolve(q(x), taps)[:4000]
    assert np.max(np.abs(y - expected)) < 1.0 / 128
    p_ratio_db = 10 * np.log10(np.mean(np.abs(y) ** 2) / np.mean(np.abs(q(x)) ** 2))
    assert p_ratio_db == pytest.approx(10 * np.log10(np.sum(np.abs(taps) ** 2)), abs=0.3)
    with pytest.raises(ValueError, match="taps must be"):
        AirChannel.from_taps(np.zeros(3))
