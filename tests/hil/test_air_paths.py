"""The emulated air's time-varying multipath: paths with fractional delays, gains and Doppler
shifts, in segments. Closed forms: the Doppler phase rate, the band-limited convolution, the
same fading through the emulated HackRF medium and the emulated Pluto, phase continuity."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from hil import AirChannel, EmulatedPluto, Medium, loopback_pair
from hil.emulation import AirPath, PathSegment
from hil.emulation.pluto_attrs import parse_air_setting
from hil.pluto.ad9361 import (
    DEFAULT_RX_GAIN_DB,
    DEFAULT_TX_GAIN_DB,
    RX_FULL_SCALE,
    TX_FULL_SCALE,
    clock_chain,
)
from hil.pluto.context import air_setting

FS = 4e6


def _radio(index):
    return SimpleNamespace(
        index=index,
        ppm=0.0,
        sample_rate_hz=FS,
        center_freq_hz=2.4e9,
        rx_gain_db=40.0,
        tx_gain_db=30.0,
    )


def through_medium(channel, x, n, medium=None):
    """``x`` through a medium's air as one burst; [n] complex64 before the ADC."""
    m = medium or Medium(channel, seed=0, wait_for_bursts=1)
    tx, rx = _radio(0), _radio(1)
    m.start_tx(tx)
    m.append_tx_iq(tx, x)
    m.end_tx(tx)
    return m.render_iq(rx, 0, n, lambda: True)


def paths_channel(paths, **kw):
    """One static-or-moving segment of ``(delay_s, gain, doppler_hz)`` paths."""
    seg = PathSegment(0.0, tuple(AirPath(*p) for p in paths))
    return AirChannel(snr_db=100, normalize_taps=False, path_segments=(seg,), **kw)


def tones(t, seed=0, num=24):
    """A band-limited test signal: complex tones within |f| <= 0.4 fs, about -17 dBFS."""
    rng = np.random.default_rng(seed)
    f = rng.uniform(-0.4, 0.4, num) * FS
    c = (rng.standard_normal(num) + 1j * rng.standard_normal(num)) * 0.03
    return np.exp(2j * np.pi * np.outer(t, f)) @ c


def nmse_db(y, ref):
    return 10 * np.log10(np.mean(np.abs(y - ref) ** 2) / np.mean(np.abs(ref) ** 2))


def test_a_path_with_doppler_turns_the_phase_at_two_pi_fd():
    """A constant carrier through one path of Doppler f_d (through the emulated HackRFs, int8
    ADC, 30 dB SNR): the received phase turns at 2 pi f_d rad/s."""
    fd = 237.0
    n = 80_000  # 20 ms: almost 5 turns
    ch = paths_channel([(0.31e-6, 0.8 + 0.3j, fd)], delay_s=2e-6)
    ch = dataclasses.replace(ch, snr_db=30.0)
    tx, rx, _ = loopback_pair(ch, ppm=(0.0, 0.0), seed=3)
    with tx, rx:
        for d in (tx, rx):
            d.sample_rate_hz = FS
            d.center_freq_hz = 2.4e9
        tx.tx(np.full(n, 0.2, np.complex64))
        y = rx.rx(n)[0]
    k = np.arange(1000, n - 1000)
    rate = np.polyfit(k / FS, np.unwrap(np.angle(y[k])), 1)[0]
    assert rate == pytest.approx(2 * np.pi * fd, rel=0.01)
    assert rate == pytest.approx(2 * np.pi * fd, rel=1e-3)  # well inside: noise averages out


def test_two_static_paths_are_the_band_limited_convolution():
    """Two paths at fractional delays over a bulk delay: the output is ``sum_i a_i x(t - D -
    tau_i)`` of the band-limited input, within the resampler's -60 dB."""
    n = 20_000
    t = np.arange(n) / FS
    x = tones(t).astype(np.complex64)
    delay, paths = 3.3e-6, [(0.0, 0.8 + 0.1j, 0.0), (1.37e-6, -0.3 + 0.4j, 0.0)]
    y = through_medium(paths_channel(paths, delay_s=delay), x, n)
    ref = sum(g * tones(t - delay - d) for d, g, _ in paths)
    inner = slice(200, n - 200)  # the burst's edges are not band-limited
    assert nmse_db(y[inner], ref[inner]) < -55


def test_integer_delay_paths_are_the_fixed_taps():
    """Paths at whole-sample delays are exactly the old integer-tap multipath."""
    x = tones(np.arange(5000) / FS).astype(np.complex64)
    taps = AirChannel(snr_db=100, multipath=((3, 0.5j), (7, -0.25)))
    paths = paths_channel([(0.0, 1.0, 0.0), (3 / FS, 0.5j, 0.0), (7 / FS, -0.25, 0.0)])
    paths = dataclasses.replace(paths, normalize_taps=True)
    assert np.allclose(through_medium(paths, x, 5000), through_medium(taps, x, 5000), atol=1e-6)


def _hackrf_capture(channel, x, n):
    tx, rx, _ = loopback_pair(channel, ppm=(0.0, 0.0), seed=7)
    with tx, rx:
        for d in (tx, rx):
            d.sample_rate_hz = FS
            d.center_freq_hz = 2.4e9
        tx.tx(x)
        return rx.rx(n)[0]


def _pluto_capture(channel, x, n):
    board = EmulatedPluto(
        dataclasses.replace(
            channel, reference_txvga_db=DEFAULT_TX_GAIN_DB, reference_rx_gain_db=DEFAULT_RX_GAIN_DB
        ),
        seed=7,
    )
    board.requested_rate_hz = int(FS)
    board.chain = clock_chain(int(FS))
    board.tx_lo_hz = board.rx_lo_hz
    raw = np.empty(2 * len(x), np.int16)
    raw[0::2] = np.rint(x.real * TX_FULL_SCALE)
    raw[1::2] = np.rint(x.imag * TX_FULL_SCALE)
    board.open_rx()
    board.open_tx(cyclic=False)
    board.write_tx(raw)
    board.close_tx()
    iq = board.read_rx(n).astype(np.float32) / RX_FULL_SCALE
    board.close_rx()
    return iq.view(np.complex64)


def test_the_emulated_hackrf_and_pluto_see_the_same_fading():
    """The same two moving paths and seed through two emulated HackRFs and through an emulated
    Pluto: both receive the same time-varying channel (that of the closed form), far from
    what the paths would give at rest."""
    n = 40_000
    t = np.arange(n) / FS
    x0 = tones(t, seed=1)
    s = 0.9 / max(np.abs(x0.real).max(), np.abs(x0.imag).max())  # peak at 0.9 full scale
    x = (s * x0).astype(np.complex64)
    paths = [(0.0, 0.7 + 0.2j, 180.0), (0.83e-6, -0.4 + 0.3j, -120.0)]
    ch = paths_channel(paths, delay_s=1e-6)
    ref = sum(
        g * np.exp(2j * np.pi * f * (t - 1e-6)) * s * tones(t - 1e-6 - d, seed=1)
        for d, g, f in paths
    )
    y_hackrf, y_pluto = _hackrf_capture(ch, x, n), _pluto_capture(ch, x, n)
    inner = slice(200, n - 200)
    assert nmse_db(y_hackrf[inner], ref[inner]) < -30
    assert nmse_db(y_pluto[inner], ref[inner]) < -30
    assert nmse_db(y_hackrf[inner], y_pluto[inner]) < -30
    at_rest = sum(g * s * tones(t - 1e-6 - d, seed=1) for d, g, _ in paths)
    assert nmse_db(y_hackrf[inner], at_rest[inner]) > -10  # the Doppler is what they share


def test_a_segment_switch_keeps_the_carrier_phase():
    """A re-trace at t1 whose gain carries the phase on (a e^{2j pi f t1}, as MovingCIR's) is
    seamless: the output equals one unbroken segment. One that does not jumps exactly at t1."""
    n, fd, t1 = 20_000, 400.0, 2501 / FS
    x = np.full(n, 0.1, np.complex64)
    a = 0.9 * np.exp(0.4j)
    whole = through_medium(paths_channel([(0.5e-6, a, fd)]), x, n)
    carried = AirChannel.from_paths(
        [[a], [a * np.exp(2j * np.pi * fd * t1)]],
        [[0.5e-6], [0.5e-6]],
        [[fd], [fd]],
        [0.0, t1],
        snr_db=100,
    )
    assert np.max(np.abs(through_medium(carried, x, n) - whole)) < 1e-6
    broken = dataclasses.replace(
        carried,
        path_segments=(carried.path_segments[0], PathSegment(t1, (AirPath(0.5e-6, a, fd),))),
    )
    y = through_medium(broken, x, n)
    step = np.abs(np.angle(y[1:] / y[:-1]))  # phase step per sample
    assert np.argmax(step[100:-100]) + 100 + 1 == 2501  # h(t, tau) switches at t = t1
    lost = np.angle(np.exp(-2j * np.pi * fd * (t1 - 1 / FS)))  # the phase the re-trace drops
    assert step[2500] == pytest.approx(abs(lost), abs=1e-3)
    assert np.max(np.delete(step, 2500)[100:-100]) < 1e-3  # elsewhere: 2 pi fd / fs + noise


def test_setting_the_channel_restarts_its_time_at_the_next_burst():
    """The Doppler phase counts from the first sample sent after ``set_channel``: a second
    burst starts at the path's own gain, whatever the medium's clock says."""
    a, fd = 0.5 + 0.5j, 300.0
    ch = paths_channel([(0.0, a, fd)])
    m = Medium(ch, seed=0, wait_for_bursts=2)
    tx, rx = _radio(0), _radio(1)
    m.start_tx(tx)
    for burst in range(2):
        if burst == 1:
            m.set_channel(ch, seed=0)
        m.start_tx(tx)
        m.append_tx_iq(tx, np.full(10_000, 0.1, np.complex64))
        m.end_tx(tx)
        m.render_iq(rx, 10_000 * burst, 5_000, lambda: True)  # the receiver reads on
    assert m.epoch == 10_000  # the second burst starts where the first ended
    y = m.render_iq(rx, 10_000, 10_000, lambda: True)
    assert np.angle(y[100] / 0.1) == pytest.approx(
        np.angle(a) + 2 * np.pi * fd * 100 / FS, abs=1e-4
    )


def test_path_air_round_trips_through_json_and_the_pluto_attribute():
    ch = AirChannel.from_paths(
        [[0.1 + 0.2j, 0.3j], [0.2, 0]],
        [[0.0, 1e-7], [0.0, 0.0]],
        [[5.0, -5.0], [7.0, 0.0]],
        [0.0, 0.01],
        snr_db=12.0,
        delay_s=1e-6,
    )
    assert [len(s.paths) for s in ch.path_segments] == [2, 1]  # zero gains are padding
    assert AirChannel.from_json(ch.to_json()) == ch
    assert parse_air_setting(air_setting(ch, 1.5, 4)) == (ch, 1.5, 4)
    assert ch.max_doppler_hz == 7.0
    with pytest.raises(ValueError, match="fir"):
        _ = ch.taps


@pytest.mark.parametrize(
    "build, field",
    [
        (lambda: AirPath(-1e-9, 1.0), "delay_s"),
        (lambda: AirPath(1.0, 1.0), "delay_s"),
        (lambda: AirPath(0.0, 1.0, 2e5), "doppler_hz"),
        (lambda: AirPath(0.0, 1.0, float("nan")), "doppler_hz"),
        (lambda: AirPath(0.0, complex("nan")), "gain"),
        (lambda: PathSegment(0.0, ()), "paths"),
        (lambda: PathSegment(-1.0, (AirPath(0.0, 1.0),)), "start_s"),
        (lambda: AirChannel(path_segments=(PathSegment(0.1, (AirPath(0.0, 1.0),)),)), "start at 0"),
        (
            lambda: AirChannel(
                path_segments=(
                    PathSegment(0.0, (AirPath(0.0, 1.0),)),
                    PathSegment(0.0, (AirPath(0.0, 1.0),)),
                )
            ),
            "strictly increase",
        ),
        (lambda: AirChannel(path_segments=(PathSegment(0.0, (AirPath(0.0, 0j),)),)), "zero"),
        (
            lambda: AirChannel(
                multipath=((2, 0.5),), path_segments=(PathSegment(0.0, (AirPath(0.0, 1.0),)),)
            ),
            "multipath",
        ),
        (lambda: AirChannel.from_paths([[1.0, 0.5]], [[0.0]]), "shape"),
    ],
)
def test_bad_paths_are_refused_naming_the_field(build, field):
    with pytest.raises(ValueError, match=field):
        build()
