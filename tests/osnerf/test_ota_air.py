"""``osnerf run --channel ota --ota-air raytraced``: each view's emulated air is its drone's
ray-traced channel (the emulated HackRFs and the emulated Pluto alike), at the SNR
convention of channel raytraced; real boards are refused; the report says what air each
view had."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from hil import IiodServer, OtaConfig
from osnerf.cli import main
from osnerf.ota_link import OtaLink, open_radios
from osnerf.run import RunConfig
from osnerf.run.ota_air import ViewAirLink, raytraced_air_links
from phy.raytrace import MovingCIR

C = 299_792_458.0


def _qpsk(gen, batch, n):
    b = torch.randint(0, 2, (batch, n, 2), generator=gen)
    return ((1 - 2 * b[..., 0]) + 1j * (1 - 2 * b[..., 1])).to(torch.complex64) / 2**0.5


class _Mover:
    """A drone whose traced paths are given (no sionna): two paths, -6 dB below a median
    position's gain of 1e-8 (path loss 80 dB), the second (0.1 % of the power, so the burst's
    gain stays within 0.3 dB of the mean) 0.1 us later with its own Doppler."""

    def __init__(self):
        g = 10 ** (-80 / 20) * 10 ** (-6 / 20)
        self.a = np.array([[g * math.sqrt(0.999) * np.exp(0.3j), g * math.sqrt(0.001) * 1j]])
        self.calls = []

    def cir(self, duration_s):
        self.calls.append(duration_s)
        return MovingCIR(np.zeros(1), self.a, np.array([[0.0, 1e-7]]), np.array([[40.0, -25.0]]))


def _radios(device, monkeypatch, tmp_board):
    cfg = OtaConfig()
    if device == "pluto":
        srv = IiodServer(tmp_board, "127.0.0.12", 0).serve_in_background()
        monkeypatch.setenv("IIOD_REMOTE", f"{srv.address}:{srv.port}")
        tx, rx, emu = open_radios("pluto", 30.0, cfg, seed=0)
        return OtaLink(tx, rx, 30.0, cfg, emu), srv
    tx, rx, emu = open_radios("emulated", 30.0, cfg, seed=0, loopback=True)
    return OtaLink(tx, rx, 30.0, cfg, emu), None


@pytest.mark.parametrize("device", ["emulated", "pluto"])
def test_a_view_sends_over_its_traced_paths_at_the_median_convention(device, monkeypatch):
    """The view's air is its paths scaled by the median position's gain: a drone 6 dB below
    the median receives 6 dB less than one at the median, on emulated HackRFs and Pluto
    alike (the same paths, the same receiver: its estimator's own bias cancels)."""
    from hil import EmulatedPluto

    board = EmulatedPluto.for_link(30.0, seed=0)
    ota, srv = _radios(device, monkeypatch, board)
    mover = _Mover()
    at_median = ViewAirLink(ota, 4, 12.0, _Mover(), 10 ** (86 / 20), device, 12.0, seed=1)
    link = ViewAirLink(ota, 5, 6.0, mover, 10 ** (80 / 20), device, 12.0, seed=1)
    x = _qpsk(torch.Generator().manual_seed(0), 2, 3000)
    try:
        ref = at_median(x, 12.0)
        out = link(x, 6.0)
        with pytest.raises(ValueError, match="runs at 6 dB, asked for 12 dB"):
            link(_qpsk(torch.Generator().manual_seed(0), 1, 100), 12.0)
    finally:
        ota.close()
        if srv is not None:
            srv.shutdown()
    air = ota.emulator.medium.channel if device == "emulated" else board.medium.channel
    paths = air.path_segments[0].paths
    assert [p.delay_s for p in paths] == [0.0, 1e-7] and [p.doppler_hz for p in paths] == [40, -25]
    np.testing.assert_allclose([p.gain for p in paths], mover.a[0] * 1e4, rtol=1e-12)
    assert air.snr_db == 12.0 and not air.normalize_taps
    assert ota.frames_lost == 0

    def snr_db(o):  # of the unbiased symbols that arrived, over all 6000
        return -10 * math.log10((o.x_hat - x).abs().pow(2).mean().item())

    assert snr_db(ref) - snr_db(out) == pytest.approx(6.0, abs=0.5)  # 6 dB of shadow
    assert snr_db(ref) == pytest.approx(12.0, abs=1.5)
    measured = ota.snr_db_measured  # the receiver's own pilot estimates agree
    assert measured[0] - measured[1] == pytest.approx(6.0, abs=1.5)
    assert link.record == {"segments": 1} and link.bursts == 1  # the refused call sent nothing
    # the burst's duration decides how far it re-traces: 2 x 3000 symbols are 4 frames of
    # 6848 samples, each after a 2000-sample gap, and a closing gap, at 4 MS/s
    assert mover.calls[0] == pytest.approx((4 * (2000 + 6848) + 2000) / 4e6)


def test_real_boards_are_refused_before_anything_is_traced():
    class Real:
        air_settable = False

    with pytest.raises(ValueError, match="real boards is not the host's to set"):
        raytraced_air_links(None, None, [0], Real(), "pluto")


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"channel": "ota", "ota_air": "nope"}, "ota_air must be one of fixed, raytraced"),
        ({"channel": "rayleigh", "ota_air": "raytraced"}, "channel ota only"),
        ({"channel": "ota", "ota_air": "raytraced", "ota_device": "hackrf"}, "real HackRFs"),
        ({"channel": "ota", "drone_speed_m_s": 15.0}, "ota with ota_air raytraced"),
    ],
)
def test_bad_air_settings_are_refused_naming_the_field(kwargs, words):
    with pytest.raises(ValueError, match=words):
        RunConfig(**kwargs)


def test_traced_air_for_real_hackrfs_is_one_line_and_creates_nothing(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["run", "--channel", "ota", "--ota-air", "raytraced", "--ota-device", "hackrf"]
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--ota-air" in err and "real HackRFs" in err
    assert not out.exists()


def test_flying_over_a_traced_air_is_allowed_and_changes_the_run():
    fixed = RunConfig(channel="ota")
    traced = RunConfig(channel="ota", ota_air="raytraced", drone_speed_m_s=15.0)
    assert fixed.key() != traced.key()


@pytest.mark.raytracing
def test_the_tiny_scene_views_fly_over_their_traced_air(tmp_path_factory):
    """The tiny plot: each view's air is its traced paths with their Doppler shifts (the line
    of sight's v . k f_c / c), each view at the SNR of channel raytraced."""
    from osnerf.run.links import build_links
    from osnerf.scenes import (
        RenderConfig,
        build_scene_dataset,
        flight_velocities,
        load_scene_views,
    )

    tiny = RenderConfig(resolution_px=16, num_train_views=4, num_test_views=1, spp=4, mask_spp=1)
    folder = build_scene_dataset(
        "tiny", ("post",), tiny, cache_dir=tmp_path_factory.mktemp("scenes"), progress=False
    )
    views = load_scene_views(folder)
    idx = [int(i) for i in views.indices("train")]
    cfg = RunConfig(
        scene="tiny", channel="ota", ota_air="raytraced", drone_speed_m_s=15.0, snr_db=10.0
    )
    traced = build_links(
        RunConfig(scene="tiny", channel="raytraced", drone_speed_m_s=15.0, snr_db=10.0), views, idx
    )
    links = build_links(cfg, views, idx)
    try:
        assert links.snr_db == pytest.approx(traced.snr_db)  # the same SNR convention
        info = links.report.to_dict()
        assert info["ota_air"] == "raytraced" and info["scene"] == "tiny"
        air_views = links.report.traced_air.air_views  # view -> what its air was
        assert sorted(air_views) == idx and info["max_doppler_hz"] > 0
        v0 = idx[0]
        links.links[v0](_qpsk(torch.Generator().manual_seed(0), 1, 2000), links.snr_db[v0])
        paths = links.ota.emulator.medium.channel.path_segments[0].paths
        k = 0
        pos, fc = views.drone_positions_m[idx], float(views.meta["carrier_frequency_hz"])
        vel = flight_velocities(views.meta, pos, 15.0)[k]
        to_station = np.asarray(views.meta["ground_station_m"]) - pos[k]
        f_los = vel @ to_station / np.linalg.norm(to_station) * fc / C
        first = min(paths, key=lambda p: p.delay_s)
        assert first.doppler_hz == pytest.approx(f_los, rel=0.01)
        assert air_views[v0]["paths"] == len(paths)
        assert links.ota.frames_lost == 0
        assert links.ota.snr_db_measured[0] == pytest.approx(links.snr_db[v0], abs=2.0)
    finally:
        links.close()
