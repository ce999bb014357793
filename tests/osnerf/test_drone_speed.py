"""``--drone-speed``: moving drones on the run's ray-traced links, what the report says about
them, the static links unchanged at rest, and bad speeds refused in one line."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from osnerf.cli import main
from osnerf.run import RunConfig
from osnerf.run.links import build_links
from osnerf.scenes import flight_velocities

C = 299_792_458.0


def _cfg(speed: float) -> RunConfig:
    return RunConfig(scene="tiny", channel="raytraced", drone_speed_m_s=speed, snr_db=10.0)


def test_flight_is_level_along_the_ring():
    meta = {"trajectory_center_m": [1.0, 2.0, 0.0]}
    pos = np.array([[11.0, 2.0, 5.0], [1.0, -8.0, 9.0], [1.0, 2.0, 20.0]])
    v = flight_velocities(meta, pos, 15.0)
    np.testing.assert_allclose(v, [[0.0, 15.0, 0.0], [15.0, 0.0, 0.0], [15.0, 0.0, 0.0]])


@pytest.mark.raytracing
def test_moving_drones_change_the_link_and_the_report_says_so(tiny_views):
    idx = tiny_views.indices("train")
    fc = float(tiny_views.meta["carrier_frequency_hz"])
    links = build_links(_cfg(15.0), tiny_views, idx)
    info = links.report.to_dict()
    fd = 15.0 * fc / C
    assert info["drone_speed_m_s"] == 15.0 and info["max_doppler_hz"] == pytest.approx(fd)
    spreads = np.array(list(info["rms_doppler_spread_hz"].values()))
    assert len(spreads) == len(idx) and np.all((spreads >= 0) & (spreads <= fd))
    assert info["median_rms_doppler_spread_hz"] == pytest.approx(np.median(spreads))
    assert "Doppler" in info["motion"]
    # each view's channel is its traced paths turning at their Doppler shifts: symbol n
    # rides subcarrier n mod 64 at time n T_s; the direct path's shift is v . k f_c / c
    import phy.raytrace as prt
    from osnerf.scenes.radio import radio_scene_path

    pos = tiny_views.drone_positions_m[idx]
    vel = flight_velocities(tiny_views.meta, pos, 15.0)
    ts = 1.0 / _cfg(15.0).symbol_rate_hz
    gs = np.asarray(tiny_views.meta["ground_station_m"])
    tracer = prt.RayTracer(
        radio_scene_path(tiny_views.folder, tiny_views.meta),
        tuple(gs),
        fc,
        prt.RayTracingConfig(max_depth=2),
    )
    n = np.arange(64 * 40)
    for k, i in enumerate(idx):
        paths = tracer.cir(pos[k], vel[k])
        a, tau, fdi = (x[0][paths.valid[0]] for x in (paths.a, paths.tau_s, paths.doppler_hz))
        assert paths.los[0] and len(a) >= 2  # the direct path and the ground's
        to_station = gs - pos[k]
        f_los = vel[k] @ to_station / np.linalg.norm(to_station) * fc / C
        assert fdi[np.argmin(tau)] == pytest.approx(f_los, rel=1e-3)
        channel = links.links[int(i)].channel
        h = channel.response(len(n))
        f = np.asarray(channel.freqs)[n % 64]
        want = (
            a * np.exp(-2j * np.pi * np.outer(f, tau) + 2j * np.pi * np.outer(n * ts, fdi))
        ).sum(1)
        ratio = h.numpy() / want  # the run's normalisation: one constant per view
        np.testing.assert_allclose(ratio, ratio[0], rtol=1e-3)
    assert not torch.allclose(h[:64], h[-64:])


@pytest.mark.raytracing
def test_at_rest_the_run_links_are_the_static_ones(tiny_views):
    from osnerf.scenes import drone_channels
    from phy import FlatLink
    from phy.raytrace import PerPositionChannel

    idx = tiny_views.indices("train")
    links = build_links(_cfg(0.0), tiny_views, idx)
    motion, trace = links.report.motion, links.report.trace
    assert motion is not None and trace is not None
    assert motion.drone_speed_m_s == 0.0 and motion.max_doppler_hz == 0.0
    assert set(motion.rms_doppler_spread_hz.values()) == {0.0}
    solver = trace.ray_solver  # what makes the run's tracing repeatable is on record
    assert solver["deterministic"] is True and solver["seed"] == 42 and solver["max_depth"] == 2
    static = drone_channels(tiny_views.folder, tiny_views.meta, tiny_views.drone_positions_m[idx])
    x = torch.ones(1, 500, dtype=torch.complex64)
    for k, i in enumerate(idx):
        old = FlatLink(PerPositionChannel(static.h[k]), csi="perfect", equalizer="zf")
        a = old(x, 3.0, generator=torch.Generator().manual_seed(k))
        b = links.links[int(i)](x, 3.0, generator=torch.Generator().manual_seed(k))
        assert torch.equal(a.x_hat, b.x_hat) and torch.equal(a.noise_var, b.noise_var)


@pytest.mark.parametrize("speed", ["-1", "100.5", "nan", "fast"])
def test_bad_speed_is_one_line_naming_the_flag_and_range(tmp_path, capsys, speed):
    out = tmp_path / "run"
    argv = ["run", "--channel", "raytraced", f"--drone-speed={speed}", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--drone-speed" in err and "[0, 100] m/s" in err
    assert not out.exists()


def test_speed_on_a_channel_without_drones_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "--channel", "rayleigh", "--drone-speed", "15", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--drone-speed" in err and "raytraced" in err
    assert not out.exists()
    with pytest.raises(ValueError, match=r"drone_speed_m_s must be a number in \[0, 100\] m/s"):
        RunConfig(channel="raytraced", drone_speed_m_s=101.0)


def test_report_header_states_speed_and_doppler():
    from osnerf.link_report import LinkReport, Motion
    from osnerf.report import motion_summary

    motion = Motion(15.0, 175.12, {0: 0.0}, 0.0, "drones fly")
    text = motion_summary(LinkReport("raytraced", motion=motion))
    assert "drone speed 15 m/s" in text and "max Doppler 175.1 Hz" in text
    assert "RMS Doppler spread 0.0 Hz" in text
    assert motion_summary(LinkReport("awgn")) == ""
