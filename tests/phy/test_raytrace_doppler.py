"""Moving drones on the ray-traced channel: Doppler against theory and against sionna-rt's
own time evolution, the time autocorrelation of a multipath channel against its paths,
re-tracing along the flight, and the static channel unchanged at rest."""

import math

import numpy as np
import pytest
import torch

import phy
from phy.raytrace import (
    RETRACE_WAVELENGTHS,
    MovingTransmitter,
    PerPositionChannel,
    RayTracedChannel,
    RayTracer,
    RayTracingConfig,
    max_doppler_hz,
)

pytestmark = pytest.mark.raytracing

C = 299_792_458.0
FC = 2.4e9
SPEED = 15.0
GRID = phy.ResourceGrid(fft_size=64, cp_length=16, subcarrier_spacing_hz=30e3)
T_SYM = GRID.symbol_length / GRID.sample_rate_hz  # OFDM symbol with its cyclic prefix
CANYON_RX = (0.0, 0.0, 1.5)
CANYON_CFG = RayTracingConfig(max_depth=2, samples_per_src=20_000, max_num_paths_per_src=20_000)
DRONE = [-40.0, 10.0, 30.0]


@pytest.fixture(scope="module")
def free_space():
    import sionna.rt as srt

    return RayTracer(srt.load_scene(), (0.0, 0.0, 0.0), FC, RayTracingConfig(max_depth=0))


@pytest.fixture(scope="module")
def canyon():
    return RayTracer("simple_street_canyon", CANYON_RX, 3.5e9, CANYON_CFG)


def _phase_steps(h: torch.Tensor) -> np.ndarray:
    """Mean phase step (radians) between successive rows of h [rows, subcarriers]."""
    return np.angle((h[1:] * h[:-1].conj()).sum(dim=1).numpy())


@pytest.mark.parametrize("angle_deg", [0.0, 60.0])
def test_los_phase_step_between_ofdm_symbols_is_doppler(free_space, angle_deg):
    """A drone 100 m away flying at 15 m/s, at ``angle_deg`` to the line towards the
    station: the received pilots turn by 2 pi f_d cos(angle) T_sym per OFDM symbol (each
    step measured over 1024 subcarriers at 60 dB)."""
    a = math.radians(angle_deg)
    ch = RayTracedChannel(
        tracer=free_space,
        tx_positions_m=[[100.0, 0.0, 0.0]],
        tx_velocities_m_s=[-SPEED * math.cos(a), SPEED * math.sin(a), 0.0],
        subcarrier_frequencies_hz=(np.arange(1024) - 512) * 30e3,
        ofdm_symbol_duration_s=T_SYM,
    )
    fd = max_doppler_hz(SPEED, FC)
    assert fd == pytest.approx(120.08, abs=0.01)
    x = torch.ones(1, 14, 1024, dtype=torch.complex64)
    out = ch(x, 60.0, generator=torch.Generator().manual_seed(0))
    measured = _phase_steps(out.y[0])  # from the noisy received grid
    expected = 2 * math.pi * fd * math.cos(a) * T_SYM
    assert np.all(np.abs(measured / expected - 1) < 0.01)
    assert ch.stats.mean_doppler_hz[0] == pytest.approx(fd * math.cos(a), rel=1e-4)
    assert ch.stats.rms_doppler_spread_hz[0] == pytest.approx(0.0, abs=1e-3)  # one path


def test_flat_mapping_turns_per_symbol_in_time_order(free_space):
    """The flat mapping sends symbol i at i * symbol_duration_s: in line of sight (a flat
    response) each symbol is turned by 2 pi f_d symbol_duration_s from the one before."""
    h0, _ = free_space.cfr([[100.0, 0.0, 0.0]], GRID.subcarrier_frequencies_hz)
    mover = MovingTransmitter(free_space, [100.0, 0.0, 0.0], [-SPEED, 0.0, 0.0])
    ts = 1e-6
    ch = PerPositionChannel(h0[0], mover, GRID.subcarrier_frequencies_hz, ts)
    h = ch.response(5000)
    steps = np.angle((h[1:] * h[:-1].conj()).numpy())
    np.testing.assert_allclose(steps, 2 * math.pi * max_doppler_hz(SPEED, FC) * ts, rtol=1e-3)
    torch.testing.assert_close(h[0], ch.h[0])  # starts at the static response
    torch.testing.assert_close(h.abs(), ch.h[0].abs().expand(5000))


def test_time_evolution_matches_sionna_paths_cfr(canyon):
    """Our per-OFDM-symbol response equals sionna-rt's Paths.cfr(sampling_frequency,
    num_time_steps) of the same moving transmitter."""
    import mitsuba as mi
    import sionna.rt as srt

    v = [12.0, -9.0, 0.0]
    scene = srt.load_scene(srt.scene.simple_street_canyon)
    scene.frequency = 3.5e9
    scene.tx_array = srt.PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    scene.rx_array = srt.PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    scene.add(srt.Transmitter("t", position=mi.Point3f(*DRONE), velocity=mi.Vector3f(*v)))
    scene.add(srt.Receiver("r", position=mi.Point3f(*CANYON_RX)))
    paths = srt.PathSolver()(scene, synthetic_array=True, **CANYON_CFG.solver_kwargs())
    f = GRID.subcarrier_frequencies_hz
    ref = paths.cfr(f, sampling_frequency=1 / T_SYM, num_time_steps=14, out_type="numpy")
    ref = np.asarray(ref).reshape(14, 64)
    mover = MovingTransmitter(canyon, DRONE, v)
    h = mover.response(np.arange(14) * T_SYM, f)
    assert np.abs(h - ref).max() / np.abs(ref).max() < 1e-4
    assert np.abs(h[-1] - h[0]).max() > 0.1 * np.abs(ref).max()  # it does change


def test_multipath_time_autocorrelation_matches_the_paths(canyon):
    """R(lag) = E[h(t + lag, f) h*(t, f)] / E|h|^2 of the generated channel, averaged over
    a flight and a wide band (which averages the paths' cross terms away), equals the one
    of the traced paths, sum_i p_i exp(2j pi f_i lag) / sum_i p_i."""
    pos, v = [30.0, 0.0, 10.0], [0.0, SPEED, 0.0]  # in the canyon, flying across it
    flight_s = RETRACE_WAVELENGTHS * (C / 3.5e9) / SPEED  # one trace: Doppler evolution only
    dt = 2e-4
    freqs = np.linspace(-1e9, 1e9, 801)  # 2 GHz: paths more than ~1 ns apart decorrelate
    ch = RayTracedChannel(
        tracer=canyon,
        tx_positions_m=[pos],
        tx_velocities_m_s=v,
        subcarrier_frequencies_hz=freqs,
        ofdm_symbol_duration_s=dt,
    )
    rows = int(flight_s / dt)
    h, _ = ch.channel_for(torch.ones(1, rows, freqs.size, dtype=torch.complex64))
    h = h[0].numpy().astype(np.complex128)  # [rows, subcarriers]
    c = canyon.cir([pos], v)
    p = np.abs(c.a[0][c.valid[0]]) ** 2
    fd = c.doppler_hz[0][c.valid[0]]
    assert len(p) > 3 and np.ptp(fd) > 0.5 * max_doppler_hz(SPEED, 3.5e9)  # spread Dopplers
    lags = np.arange(0, rows // 2, 5)
    measured = np.array([np.mean(h[k:] * h[: rows - k].conj()) for k in lags])
    measured /= np.mean(np.abs(h) ** 2)
    expected = (p * np.exp(2j * np.pi * np.outer(lags * dt, fd))).sum(axis=1) / p.sum()
    assert np.abs(expected).min() < 0.7  # the channel decorrelates within the lags
    assert np.abs(measured - expected).max() < 0.05
    spread = ch.stats.rms_doppler_spread_hz[0]
    assert spread == pytest.approx(
        math.sqrt(np.sum(p * fd**2) / p.sum() - (np.sum(p * fd) / p.sum()) ** 2), rel=1e-3
    )


def test_long_flight_is_retraced_with_continuous_phase(free_space):
    """A flight of 6 m (48 wavelengths at 2.4 GHz) is re-traced every 4 wavelengths: the
    amplitude follows free-space loss along the way and the phase runs on smoothly."""
    start = np.array([150.0, 0.0, 0.0])
    mover = MovingTransmitter(free_space, start, [-SPEED, 0.0, 0.0])
    duration = 6.0 / SPEED
    t = np.linspace(0, duration, 4001)
    before = free_space.num_traced
    h = mover.response(t, [0.0])[:, 0]
    wavelength = C / FC
    segments = math.ceil(6.0 / (RETRACE_WAVELENGTHS * wavelength))
    assert len(mover.cir(duration).start_s) == segments
    assert free_space.num_traced - before == segments
    friis = wavelength / (4 * math.pi * (150.0 - SPEED * mover.cir(duration).start_s))
    seg = np.searchsorted(mover.cir(duration).start_s, t, side="right") - 1
    np.testing.assert_allclose(np.abs(h), friis[seg], rtol=1e-3)
    steps = np.angle(h[1:] * h[:-1].conj())
    expected = 2 * math.pi * max_doppler_hz(SPEED, FC) * (t[1] - t[0])
    # no jump at a re-trace beyond the tracer's 0.1 mm position rounding (2.6 mrad here)
    assert np.abs(steps - expected).max() < 0.005


def test_at_rest_the_static_channel_is_reproduced_exactly(canyon):
    pos = [DRONE, [20.0, 0.0, 30.0]]
    static = RayTracedChannel(tracer=canyon, tx_positions_m=pos)
    rest = RayTracedChannel(tracer=canyon, tx_positions_m=pos, tx_velocities_m_s=[0.0, 0.0, 0.0])
    for x in (
        torch.ones(2, 14, 64, dtype=torch.complex64),
        torch.ones(2, 500, dtype=torch.complex64),
    ):
        a = static(x, 5.0, generator=torch.Generator().manual_seed(3))
        b = rest(x, 5.0, generator=torch.Generator().manual_seed(3))
        assert torch.equal(a.y, b.y) and torch.equal(a.h, b.h)
    h0 = static.h[0]
    mover = MovingTransmitter(canyon, DRONE, [0.0, 0.0, 0.0])
    a = PerPositionChannel(h0)(
        torch.ones(1, 300, dtype=torch.complex64), 5.0, torch.Generator().manual_seed(4)
    )
    b = PerPositionChannel(h0, mover, static.subcarrier_frequencies_hz, 1e-6)(
        torch.ones(1, 300, dtype=torch.complex64), 5.0, torch.Generator().manual_seed(4)
    )
    assert torch.equal(a.y, b.y) and torch.equal(a.h, b.h)


def test_bad_motion_input(canyon):
    with pytest.raises(ValueError, match="ofdm_symbol_duration_s must be > 0"):
        RayTracedChannel(tracer=canyon, tx_positions_m=[DRONE], tx_velocities_m_s=[1.0, 0, 0])
    with pytest.raises(ValueError, match=r"tx_velocities_m_s must be \[3\] or \[num_positions=1"):
        RayTracedChannel(tracer=canyon, tx_positions_m=[DRONE], tx_velocities_m_s=[[1.0, 0, 0]] * 2)
    with pytest.raises(
        ValueError, match=r"tx_velocities_m_s must be \[num_positions, 3\] finite m/s"
    ):
        canyon.cir([DRONE], [[float("nan"), 0.0, 0.0]])
