"""Ray-traced channel: free-space closed form, CIR -> CFR against sionna's own paths.cfr,
outage without NaN, caching, the Channel interface, bad input."""

import math

import numpy as np
import pytest
import torch

import phy
from phy.raytrace import RayTracedChannel, RayTracer, RayTracingConfig, builtin_scenes

pytestmark = pytest.mark.raytracing

C = 299_792_458.0
FC = 3.5e9
RX = (0.0, 0.0, 1.5)
CFG = RayTracingConfig(max_depth=2, samples_per_src=20_000, max_num_paths_per_src=20_000)
# drone positions above the street canyon, plus one far behind the buildings at ground
# level that no path reaches with these settings (outage)
POSITIONS = [[20.0, 0.0, 30.0], [-40.0, 10.0, 30.0], [0.0, 0.0, 2.0]]
BLOCKED = [-80.0, -50.0, 1.5]
FREQS = (np.arange(64) - 32) * 15e3


@pytest.fixture(scope="module")
def tracer():
    return RayTracer("simple_street_canyon", RX, FC, CFG)


def test_free_space_path_gain_is_friis():
    import sionna.rt as srt

    tr = RayTracer(srt.load_scene(), (0.0, 0.0, 0.0), FC, RayTracingConfig(max_depth=0))
    d = np.array([10.0, 100.0, 1000.0])
    pos = np.stack([d, np.zeros(3), np.zeros(3)], axis=1)
    s = tr.stats(pos)
    friis_db = -20 * np.log10(4 * math.pi * d * FC / C)
    np.testing.assert_allclose(s.path_gain_db, friis_db, atol=0.01)
    assert s.num_paths.tolist() == [1, 1, 1] and s.los.all() and not s.outage.any()
    assert np.all(s.rms_delay_spread_s == 0) and np.all(np.isinf(s.k_factor))
    h, outage = tr.cfr(pos, FREQS)
    # one path at relative delay 0: flat response of magnitude sqrt(gain)
    np.testing.assert_allclose(
        h.abs().numpy(), np.sqrt(10 ** (friis_db / 10))[:, None] * np.ones(64), rtol=1e-3
    )


def test_two_ray_metal_plate_delays_powers_and_stats():
    """LoS + one specular bounce off sionna's 1 m metal plate (z = 0), antennas 1 m above it
    and 0.6 m apart: delays, powers and stats against the two-ray geometry."""
    tr = RayTracer(
        "simple_reflector", (-0.3, 0.0, 1.0), FC, RayTracingConfig(max_depth=1, refraction=False)
    )
    c = tr.cir([[0.3, 0.0, 1.0]])
    assert c.valid.sum() == 2 and c.los.all()
    d1, d2 = 0.6, math.hypot(0.6, 2.0)
    delta = (d2 - d1) / C
    np.testing.assert_allclose(np.sort(c.tau_s[0]), [0.0, delta], rtol=1e-4, atol=1e-13)
    p = np.abs(c.a[0][np.argsort(c.tau_s[0])]) ** 2  # [LoS, reflected]
    friis = (C / (4 * math.pi * FC * np.array([d1, d2]))) ** 2
    assert abs(p[0] / friis[0] - 1) < 1e-3
    assert 0.98 < p[1] / friis[1] <= 1.0  # |reflection coefficient|^2 of metal
    s = tr.stats([[0.3, 0.0, 1.0]])
    np.testing.assert_allclose(s.k_factor, [p[0] / p[1]], rtol=1e-4)
    np.testing.assert_allclose(
        s.rms_delay_spread_s, [math.sqrt(p[0] * p[1]) / p.sum() * delta], rtol=1e-3
    )
    np.testing.assert_allclose(s.path_gain_db, [10 * math.log10(p.sum())], atol=1e-4)


def test_cir_to_cfr_matches_sionna_paths_cfr(tracer):
    import mitsuba as mi
    import sionna.rt as srt

    scene = srt.load_scene(srt.scene.simple_street_canyon)
    scene.frequency = FC
    scene.tx_array = srt.PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    scene.rx_array = srt.PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    for i, p in enumerate(POSITIONS):
        scene.add(srt.Transmitter(f"t{i}", position=mi.Point3f(*p)))
    scene.add(srt.Receiver("r", position=mi.Point3f(*RX)))
    paths = srt.PathSolver()(scene, synthetic_array=True, **CFG.solver_kwargs())
    ref = paths.cfr(FREQS, normalize_delays=True, out_type="torch")  # [1, 1, 3, 1, 1, 64]
    ref = torch.as_tensor(ref).reshape(len(POSITIONS), 64)
    h, outage = tracer.cfr(POSITIONS, FREQS)
    assert not outage.any()
    err = (h - ref).abs().max() / ref.abs().max()
    assert err < 1e-5


def test_outage_is_reported_not_nan(tracer):
    h, outage = tracer.cfr([POSITIONS[0], BLOCKED], FREQS)
    assert outage.tolist() == [False, True]
    assert torch.all(h[1] == 0) and torch.isfinite(h.real).all()
    s = tracer.stats([BLOCKED])
    assert s.outage.tolist() == [True] and s.num_paths.tolist() == [0]
    assert s.records()[0]["path_gain_db"] is None and s.rms_delay_spread_s[0] == 0
    ch = RayTracedChannel(tx_positions_m=[BLOCKED], tracer=tracer, fft_size=8)
    x = torch.ones(1, 16, dtype=torch.complex64)
    out = ch(x, 10.0, generator=torch.Generator().manual_seed(0))
    assert out.outage.tolist() == [True] and torch.all(out.h == 0)
    assert torch.isfinite(out.y.real).all() and torch.isfinite(out.equalized("mmse").real).all()


def test_cache_avoids_retracing(tracer):
    tracer.cfr(POSITIONS, FREQS)
    before = tracer.num_traced
    h1, _ = tracer.cfr(POSITIONS[::-1], FREQS[:8])  # same positions, other subcarriers
    assert tracer.num_traced == before
    h2, _ = tracer.cfr(POSITIONS, FREQS)
    torch.testing.assert_close(h1, h2.flip(0)[:, :8])


def test_stats_are_physical(tracer):
    s = tracer.stats(POSITIONS)
    # the 0.5 m link is much stronger than the 30 m-high drones and dominated by LoS
    assert s.path_gain_db[2] > s.path_gain_db[0] + 20 and s.los[2] and s.k_factor_db[2] > 10
    assert np.all(s.rms_delay_spread_s > 0) and np.all(s.rms_delay_spread_s < 1e-6)
    assert np.all(s.num_paths >= 1)


def test_channel_per_position_normalisation_and_noise(tracer):
    ch = RayTracedChannel(tx_positions_m=POSITIONS, tracer=tracer, fft_size=64)
    torch.testing.assert_close(ch.h.abs().pow(2).mean(dim=1), torch.ones(3), rtol=1e-5, atol=0)
    g = torch.Generator().manual_seed(1)
    x = phy.power_normalize(torch.randn(3, 64 * 200, dtype=torch.complex64, generator=g))
    x.requires_grad_(True)
    out = ch(x, 10.0, generator=g)
    # flat symbols: symbol i rides subcarrier i % 64
    torch.testing.assert_close(out.h[:, 64 + 5], ch.h[:, 5])
    noise = (out.y - out.h * x).detach()
    assert abs(noise.abs().pow(2).mean().item() / 0.1 - 1) < 0.03
    out.y.abs().pow(2).sum().backward()
    assert x.grad is not None and torch.isfinite(x.grad.real).all()
    # OFDM-shaped input: the same h on every OFDM symbol
    xo = torch.ones(3, 14, 64, dtype=torch.complex64)
    assert ch(xo, 10.0).h.shape == (3, 1, 64)


def test_channel_absolute_gain_keeps_path_loss(tracer):
    ref_db = -70.0
    ch = RayTracedChannel(
        tx_positions_m=POSITIONS,
        tracer=tracer,
        gain_normalization="absolute",
        reference_path_gain_db=ref_db,
    )
    h, _ = tracer.cfr(POSITIONS, ch.subcarrier_frequencies_hz)
    expected = h.abs().pow(2).mean(dim=1) * 10 ** (-ref_db / 10)
    torch.testing.assert_close(ch.h.abs().pow(2).mean(dim=1), expected, rtol=1e-4, atol=0)


def test_registered_as_a_phy_channel(tracer):
    ch = phy.make_channel("raytraced", tracer=tracer, tx_positions_m=POSITIONS[:1], fft_size=16)
    assert isinstance(ch, phy.Channel) and ch.h.shape == (1, 16)


def test_digital_baseline_over_ray_traced_links(tracer):
    """Bytes through the ray-traced CFR: flat (perfect CSI) and OFDM with LS pilots."""
    from phy.digital import transmit_bytes

    payload = bytes(range(200))
    flat = phy.FlatLink(
        RayTracedChannel(tx_positions_m=[POSITIONS[0]], tracer=tracer), equalizer="zf"
    )
    res = transmit_bytes(payload, "16qam-1/2", flat, 20.0, torch.Generator().manual_seed(0))
    assert res.ok and res.payload == payload
    grid = phy.ResourceGrid(fft_size=64, subcarrier_spacing_hz=240e3)  # 15 MHz wide
    ch = RayTracedChannel(
        tx_positions_m=[POSITIONS[1]],
        tracer=tracer,
        subcarrier_frequencies_hz=grid.subcarrier_frequencies_hz,
    )
    assert ch.stats.num_paths[0] > 1  # frequency-selective
    ofdm = phy.OFDMLink(grid, ch, csi="ls", equalizer="zf")
    res = transmit_bytes(payload, "qpsk-1/2", ofdm, 15.0, torch.Generator().manual_seed(1))
    assert res.ok and res.payload == payload


def test_bad_input(tracer):
    for bad in ([[1.0, 2.0]], [[0.0, 0.0, float("nan")]], "up", [[[1, 2, 3]]], []):
        with pytest.raises(ValueError, match=r"tx_positions_m must be \[num_positions, 3\]"):
            tracer.cfr(bad, FREQS)
    with pytest.raises(ValueError, match="subcarrier_frequencies_hz"):
        tracer.cfr(POSITIONS, [[1.0, 2.0]])
    with pytest.raises(KeyError, match="simple_street_canyon"):
        RayTracer("atlantis")
    assert "munich" in builtin_scenes()
    with pytest.raises(FileNotFoundError, match="does not exist"):
        RayTracer("/nonexistent/scene.xml")
    with pytest.raises(ValueError, match="carrier_frequency_hz"):
        RayTracer("simple_street_canyon", carrier_frequency_hz=-1.0)
    with pytest.raises(ValueError, match="max_depth must be an integer in"):
        RayTracingConfig(max_depth=-1)
    with pytest.raises(ValueError, match="gain_normalization must be one of"):
        RayTracedChannel(tracer=tracer, gain_normalization="free")
    with pytest.raises(ValueError, match="reference_path_gain_db"):
        RayTracedChannel(tracer=tracer, gain_normalization="absolute")
    ch = RayTracedChannel(tx_positions_m=POSITIONS, tracer=tracer)
    with pytest.raises(ValueError, match="batch must equal num_positions"):
        ch(torch.ones(2, 10, dtype=torch.complex64), 10.0)
    with pytest.raises(ValueError, match="x must be a complex64"):
        ch(torch.ones(3, 10), 10.0)
