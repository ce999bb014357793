"""Channels: noise variance, fading statistics, registry, gradients, bad input."""

import math

import pytest
import torch

import phy

FLAT = ["awgn", "rayleigh", "rayleigh_fast", "rician", "rician_fast"]


def _unit_symbols(batch, n, seed=0):
    g = torch.Generator().manual_seed(seed)
    return phy.power_normalize(torch.randn(batch, n, dtype=torch.complex64, generator=g))


def test_awgn_noise_variance_within_one_percent():
    x = _unit_symbols(1, 1_000_000)
    out = phy.AWGN()(x, 7.0, generator=torch.Generator().manual_seed(1))
    nv = 10 ** (-0.7)
    e = out.y - x
    assert abs(e.abs().pow(2).mean().item() / nv - 1) < 0.01
    # noise_var/2 per real dimension, real and imaginary uncorrelated
    assert abs(e.real.var().item() / (nv / 2) - 1) < 0.01
    assert abs(e.imag.var().item() / (nv / 2) - 1) < 0.01
    assert abs((e.real * e.imag).mean().item()) < 0.01 * nv
    assert torch.allclose(out.noise_var, torch.tensor([nv], dtype=torch.float32))


def test_per_example_snr_gives_per_example_noise():
    x = _unit_symbols(2, 200_000)
    out = phy.AWGN()(x, torch.tensor([0.0, 20.0]), generator=torch.Generator().manual_seed(2))
    measured = (out.y - x).abs().pow(2).mean(dim=1)
    assert torch.allclose(measured, torch.tensor([1.0, 0.01]), rtol=0.02)


@pytest.mark.parametrize("name", ["rayleigh", "rayleigh_fast", "rician", "rician_fast"])
def test_fading_has_unit_mean_power(name):
    # 20k rows with block fading: E|h|^2 = 1 within 4 sigma (sd of |h|^2 <= 1 per draw)
    x = torch.ones(20_000, 50, dtype=torch.complex64)
    out = phy.make_channel(name)(x, 30.0, generator=torch.Generator().manual_seed(3))
    p = out.h.abs().pow(2)
    n = p.numel()
    assert abs(p.mean().item() - 1.0) < 4.0 / math.sqrt(n)
    assert out.h.shape == ((20_000, 1) if name in ("rayleigh", "rician") else (20_000, 50))
    torch.testing.assert_close(out.y - out.h * x, out.y - out.h * x)  # shape-broadcast sanity


def test_rayleigh_amplitude_is_rayleigh_distributed():
    # P(|h|^2 < t) = 1 - exp(-t) for h ~ CN(0, 1)
    out = phy.RayleighFading("fast")(
        torch.ones(1, 400_000, dtype=torch.complex64),
        30.0,
        generator=torch.Generator().manual_seed(4),
    )
    g = out.h.abs().pow(2)
    for t in (0.1, 0.5, 1.0, 2.0):
        p = 1 - math.exp(-t)
        assert abs((g < t).float().mean().item() - p) < 4 * math.sqrt(p * (1 - p) / g.numel())


def test_rician_k_factor_and_los_phase():
    k_db = 10.0
    ch = phy.RicianFading(k_factor_db=k_db, mode="fast", los_phase_rad=0.5)
    out = ch(
        torch.ones(1, 200_000, dtype=torch.complex64),
        30.0,
        generator=torch.Generator().manual_seed(5),
    )
    k = 10 ** (k_db / 10)
    los = out.h.mean()
    assert abs(los.abs().item() ** 2 - k / (k + 1)) < 0.01
    assert abs(torch.angle(los).item() - 0.5) < 0.01
    scatter = (out.h - los).abs().pow(2).mean().item()
    assert abs(scatter - 1 / (k + 1)) < 0.01 / (k + 1) * 10


def test_generator_makes_draws_reproducible():
    x = _unit_symbols(3, 64)
    a = phy.make_channel("rician")(x, 5.0, generator=torch.Generator().manual_seed(9))
    b = phy.make_channel("rician")(x, 5.0, generator=torch.Generator().manual_seed(9))
    c = phy.make_channel("rician")(x, 5.0, generator=torch.Generator().manual_seed(10))
    assert torch.equal(a.y, b.y) and torch.equal(a.h, b.h)
    assert not torch.equal(a.y, c.y)


@pytest.mark.parametrize("name", FLAT)
def test_every_flat_channel_builds_and_is_differentiable(name):
    x = _unit_symbols(2, 32).requires_grad_(True)
    out = phy.make_channel(name)(x, 10.0, generator=torch.Generator().manual_seed(0))
    assert out.y.shape == x.shape and out.y.dtype == torch.complex64
    assert out.noise_var.shape == (2,)
    (out.y.real.sum() + out.y.imag.sum()).backward()
    assert x.grad is not None and torch.isfinite(x.grad.real).all()


def test_registry_lists_the_required_names():
    for name in ("awgn", "rayleigh", "rayleigh_fast", "rician", "tdl", "cdl"):
        assert name in phy.CHANNELS


def test_unknown_channel_names_the_known_ones():
    with pytest.raises(KeyError, match="known: .*awgn"):
        phy.make_channel("rayleigh_slow")


@pytest.mark.parametrize(
    "bad, match",
    [
        (torch.ones(2, 4), "complex64"),
        (torch.ones(4, dtype=torch.complex64), r"\[batch, num_symbols\]"),
        ([1, 2], "torch.Tensor"),
    ],
)
def test_bad_symbols_get_one_line_error(bad, match):
    with pytest.raises(ValueError, match=match):
        phy.AWGN()(bad, 10.0)


@pytest.mark.parametrize("snr", [float("nan"), 100.0, -50.0, "ten"])
def test_snr_out_of_range_is_refused(snr):
    with pytest.raises(ValueError, match="snr_db"):
        phy.RayleighFading()(torch.ones(1, 4, dtype=torch.complex64), snr)


def test_bad_channel_parameters():
    with pytest.raises(ValueError, match="mode must be one of"):
        phy.RayleighFading(mode="slow")
    with pytest.raises(ValueError, match="k_factor_db"):
        phy.RicianFading(k_factor_db=99)
