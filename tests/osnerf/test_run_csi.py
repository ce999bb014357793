"""``--csi``: the run's ray-traced link over an OFDM grid with pilots, LS or LMMSE estimates;
the copies of a view sent one after the other along the flight; bad values refused in one
line naming the flag."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import phy
from osnerf.cli import main
from osnerf.run import RunConfig
from osnerf.run.links import (
    RAYTRACED_GRID,
    build_links,
    raytraced_estimator,
    raytraced_link,
)
from phy.raytrace import MovingCIR, PerPositionChannel

C = 299_792_458.0
FC = 3.5e9
GRID_F = RAYTRACED_GRID.subcarrier_frequencies_hz


class _Mover:
    """A ``phy.raytrace.MovingTransmitter``'s interface over a hand-built :class:`MovingCIR`."""

    def __init__(self, cir: MovingCIR, speed_m_s: float):
        self.cir, self.speed_m_s = cir, speed_m_s

    def response(self, rows, freqs, cols=None):
        return self.cir.response(rows, freqs, cols)


def _multipath(speed_m_s: float) -> _Mover:
    """A strong first path and three weaker ones (no deep notch), leaving at fixed angles
    to the velocity: path i's Doppler is ``cos(angle_i) v f_c / c``."""
    rng = np.random.default_rng(1)
    a = np.array([1.0, 0.3, 0.2, 0.1]) * np.exp(2j * np.pi * rng.uniform(size=4))
    tau = np.array([0.0, 60e-9, 150e-9, 300e-9])
    fd = np.array([1.0, -0.5, 0.3, -0.9]) * speed_m_s * FC / C
    return _Mover(MovingCIR(np.zeros(1), a[None], tau[None], fd[None]), speed_m_s)


def _cfg(csi, speed: float = 0.0) -> RunConfig:
    return RunConfig(scene="tiny", channel="raytraced", csi=csi, drone_speed_m_s=speed, snr_db=10.0)


@pytest.mark.raytracing
def test_ls_at_rest_matches_perfect_csi_within_the_estimation_noise(tiny_views):
    idx = tiny_views.indices("train")
    links = build_links(_cfg("ls"), tiny_views, idx)
    grid = links.report.to_dict()["grid"]  # the pilot pattern and its spacing in time are on record
    t_sym = 80 / (64 * 30e3)
    assert grid["pilot_ofdm_symbols"] == [2, 11] and grid["pilot_subcarrier_spacing"] == 1
    assert grid["max_pilot_spacing_s"] == pytest.approx(9 * t_sym)
    assert "linear interpolation" in links.report.to_dict()["csi"]
    x = phy.qpsk_pilots(1, 4 * RAYTRACED_GRID.num_data_symbols, torch.Generator().manual_seed(0))
    snr_db, nv = 20.0, 10 ** (-20.0 / 10)
    ratios = []
    for i in idx:
        link = links.links[int(i)]
        assert isinstance(link, phy.OFDMLink) and link.csi == "ls"
        genie = phy.OFDMLink(RAYTRACED_GRID, link.channel, csi="perfect", equalizer="zf")
        ls = link(x, snr_db, generator=torch.Generator().manual_seed(int(i)))
        ref = genie(x, snr_db, generator=torch.Generator().manual_seed(int(i)))  # same noise
        # ZF with h_hat = h + e: x_hat_ls - x_hat = -x e / h to first order, whose variance
        # is the estimation error's share of the reported noise variance
        ok = ref.noise_var < 4 * nv  # |h|^2 > 1/4: first order holds
        gap = (ls.x_hat - ref.x_hat).abs().pow(2)[ok].mean()
        extra = (ls.noise_var - ref.noise_var)[ok].mean()
        assert extra > 0
        ratios.append(float(gap / extra))
    assert 0.8 < np.mean(ratios) < 1.25, ratios


@pytest.mark.raytracing
def test_copies_of_a_view_fly_on_when_moving_and_repeat_at_rest(tiny_views):
    idx = [int(i) for i in tiny_views.indices("train")]
    x = torch.ones(2, 640, dtype=torch.complex64)
    for speed in (0.0, 15.0):
        for csi in (None, "ls"):
            links = build_links(_cfg(csi, speed), tiny_views, idx)
            ch = links.links[idx[0]].channel
            xx = (
                x
                if csi is None
                else phy.map_to_grid(x.new_ones(2, RAYTRACED_GRID.num_data_symbols), RAYTRACED_GRID)
            )
            h = ch(xx, 10.0, generator=torch.Generator().manual_seed(0)).h
            assert torch.equal(h[0], h[1]) == (speed == 0.0), (speed, csi)


def test_copies_continue_in_time_on_a_moving_channel():
    mover = _multipath(15.0)
    h0 = mover.response([0.0], GRID_F)[0]
    ch = PerPositionChannel(h0, mover, GRID_F, 1e-6, ofdm_symbol_duration_s=40e-6)
    gen = torch.Generator().manual_seed(0)
    flat = ch(torch.ones(3, 500, dtype=torch.complex64), 10.0, generator=gen).h
    one = ch(torch.ones(1, 1500, dtype=torch.complex64), 10.0, generator=gen).h
    torch.testing.assert_close(flat, one.reshape(3, 500))  # copy b starts where b - 1 ended
    assert not torch.allclose(flat[0], flat[2])
    grid = ch(torch.ones(2, 14, 64, dtype=torch.complex64), 10.0, generator=gen).h
    long = ch(torch.ones(1, 28, 64, dtype=torch.complex64), 10.0, generator=gen).h
    torch.testing.assert_close(grid, long.reshape(2, 14, 64))
    want = mover.response(np.arange(28) * 40e-6, GRID_F) / np.sqrt(np.mean(np.abs(h0) ** 2))
    np.testing.assert_allclose(long[0].numpy(), want, rtol=1e-5, atol=1e-6)
    rest = PerPositionChannel(h0)(torch.ones(2, 14, 64, dtype=torch.complex64), 10.0).h
    assert torch.equal(rest[0], rest[1])


def test_ls_error_grows_with_speed_and_lmmse_is_no_worse():
    n = 20 * RAYTRACED_GRID.num_data_symbols  # 20 slots, about 12 ms
    x = phy.qpsk_pilots(1, n, torch.Generator().manual_seed(0))
    mse = {}
    for speed in (0.0, 15.0, 30.0):
        mover = _multipath(speed)
        h0 = mover.response([0.0], GRID_F)[0]
        for csi in ("ls", "lmmse"):
            cfg = _cfg(csi, speed)
            link = raytraced_link(cfg, h0, mover, raytraced_estimator(cfg, FC))
            out = link(x, 30.0, generator=torch.Generator().manual_seed(5))
            mse[csi, speed] = float((out.x_hat - x).abs().pow(2).mean())
    assert mse["ls", 0.0] < mse["ls", 15.0] < mse["ls", 30.0], mse
    assert mse["ls", 30.0] > 3 * mse["ls", 0.0], mse  # the channel turns between pilots
    for speed in (0.0, 15.0, 30.0):
        assert mse["lmmse", speed] <= mse["ls", speed], mse


def test_default_csi_keeps_the_flat_perfect_link():
    mover = _multipath(15.0)
    h0 = mover.response([0.0], GRID_F)[0]
    for csi in (None, "perfect"):
        link = raytraced_link(_cfg(csi, 15.0), h0, mover)
        assert isinstance(link, phy.FlatLink) and link.csi == "perfect"


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--channel", "raytraced", "--csi", "mmse"], ["--csi", "lmmse"]),
        (["--channel", "rayleigh", "--csi", "ls"], ["--csi", "raytraced"]),
        (["--channel", "tdl", "--csi", "lmmse"], ["--csi", "raytraced"]),
    ],
)
def test_bad_csi_is_one_line_naming_the_flag(tmp_path, capsys, argv, words):
    out = tmp_path / "run"
    assert main(["run", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(w in err for w in words), err
    assert not out.exists()
    with pytest.raises(ValueError, match=r"csi must be one of perfect, ls, lmmse"):
        RunConfig(channel="raytraced", csi="mmse")
