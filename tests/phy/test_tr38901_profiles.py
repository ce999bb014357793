"""TR 38.901 spec_version pinned, validated and recorded; the TS 38.101-4 fixed TDL profiles
and their propagation conditions as named channels, against the standard's tables."""

import math

import numpy as np
import pytest
import torch
from scipy.special import j0

import phy
from phy.channels.tr38901 import FIXED_TDL_PROFILES, SPEC_VERSION, SPEC_VERSIONS

C = 299_792_458.0
# TS 38.101-4 Annex B.2.1 (FR1), tap delays in ns and powers in dB, as the standard tabulates
STANDARD = {
    "A30": (
        [0, 10, 15, 20, 25, 50, 65, 75, 105, 135, 150, 290],
        [-15.5, 0, -5.1, -5.1, -9.6, -8.2, -13.1, -11.5, -11.0, -16.2, -16.6, -26.2],
    ),
    "B100": (
        [0, 10, 20, 30, 35, 45, 55, 120, 170, 245, 330, 480],
        [0, -2.2, -0.6, -0.6, -0.3, -1.2, -5.9, -2.2, -0.8, -6.3, -7.5, -7.1],
    ),
    "C300": (
        [0, 65, 70, 190, 195, 200, 240, 325, 520, 1045, 1510, 2595],
        [-6.9, 0, -7.7, -2.5, -2.4, -9.9, -8.0, -6.6, -7.1, -13.0, -14.2, -16.0],
    ),
}
CONDITIONS = [n for n, f in phy.CHANNELS.items() if hasattr(f, "profile")]


def _rms_delay_spread_s(delays, powers) -> float:
    p = powers / powers.sum()
    mean = (p * delays).sum()
    return float(((p * (delays - mean) ** 2).sum()).sqrt())


def test_spec_version_is_pinned_and_reaches_sionna():
    for cls in (phy.TDLChannel, phy.CDLChannel):
        ch = cls()
        assert ch.spec_version == SPEC_VERSION == "19.2"
        assert ch._model().spec_version == SPEC_VERSION  # what sionna's tables are read from
        assert cls(spec_version="16.1")._model().spec_version == "16.1"


def test_the_versions_we_allow_are_the_ones_sionna_ships():
    from sionna.phy.channel.tr38901 import models

    assert set(SPEC_VERSIONS) == set(models._VERSION_DIRS)


@pytest.mark.parametrize("bad", ["19.3", "V19.2", 19.2, None])
def test_invalid_spec_version_is_a_one_line_error_naming_field_and_values(bad):
    for name in ("tdl", "cdl", "tdla30-10"):
        with pytest.raises(ValueError) as e:
            phy.make_channel(name, spec_version=bad)
        msg = str(e.value)
        assert "\n" not in msg and msg.startswith("spec_version must be one of 16.1, 19.2")


@pytest.mark.parametrize("name", ["tdl", "cdl", "tdlc300-600"])
def test_every_tr38901_result_records_the_spec_version(name):
    rec = phy.channel_record(phy.channel_link(name))
    assert rec["channel"] == name and rec["spec_version"] == SPEC_VERSION
    assert rec["model"] == {"tdl": "TDL-A", "cdl": "CDL-A"}.get(name, "TDL-C300")
    assert phy.channel_record(phy.channel_link("awgn")) == {"channel": "awgn"}


@pytest.mark.parametrize("profile", sorted(STANDARD))
def test_fixed_profiles_have_the_standards_power_delay_profile(profile):
    delays, powers = phy.TDLChannel(profile).power_delay_profile
    want_d, want_p = STANDARD[profile]
    np.testing.assert_allclose(delays.numpy() * 1e9, want_d, atol=1e-3)
    want = 10 ** (np.array(want_p) / 10)
    np.testing.assert_allclose(powers.numpy(), want / want.sum(), rtol=1e-5)


@pytest.mark.parametrize("profile", list(FIXED_TDL_PROFILES))
def test_fixed_profiles_have_the_delay_spread_of_their_name(profile):
    ch = phy.TDLChannel(profile)
    assert ch.delay_spread_s == FIXED_TDL_PROFILES[profile]
    spread = _rms_delay_spread_s(*ch.power_delay_profile)
    assert spread == pytest.approx(FIXED_TDL_PROFILES[profile], rel=0.02)
    with pytest.raises(ValueError, match=f"delay_spread_s must be .* profile {profile}"):
        phy.TDLChannel(profile, delay_spread_s=1e-6)


def test_every_condition_builds_runs_over_ofdm_and_states_its_profile_and_doppler():
    assert len(CONDITIONS) == 17  # TS 38.101-4 Tables B.2.2-1 (FR1) and B.2.2-2 (FR2)
    x = torch.ones(2, 3, 64, dtype=torch.complex64)
    for name in CONDITIONS:
        f = phy.CHANNELS[name]
        assert name == f"tdl{f.profile.lower()}-{f.max_doppler_hz:g}"
        assert name in phy.OFDM_CHANNELS and phy.assumed_channel(name) == name
        ch = phy.make_channel(name)
        assert ch.kind == name and phy.channel_kind(phy.channel_link(name)) == name
        assert ch.model == f.profile and ch.max_doppler_hz == pytest.approx(f.max_doppler_hz)
        assert ch.max_speed_m_s == pytest.approx(f.max_doppler_hz * C / 3.5e9)
        out = ch(x, 20.0, generator=torch.Generator().manual_seed(0))
        assert out.h.shape == x.shape and torch.isfinite(out.h.abs()).all()


def test_a_condition_fixes_its_profile_and_doppler():
    with pytest.raises(ValueError, match="tdla30-10 fixes max_doppler_hz, model"):
        phy.make_channel("tdla30-10", model="B", max_doppler_hz=5.0)
    ch = phy.make_channel("tdla30-10", carrier_frequency_hz=28e9)  # the Doppler stays 10 Hz
    assert ch.max_doppler_hz == pytest.approx(10.0) and ch.max_speed_m_s < 0.2
    with pytest.raises(ValueError, match="max_doppler_hz sets the speed"):
        phy.TDLChannel("A30", max_doppler_hz=10.0, max_speed_m_s=3.0)


def test_a_conditions_doppler_is_the_time_correlation_of_its_response():
    """Rayleigh taps with a maximum Doppler f_D: E[H(t + dt) H*(t)] / E|H|^2 = J0(2 pi f_D dt)."""
    ch = phy.make_channel("tdlc300-600")
    h = ch(
        torch.ones(400, 6, 64, dtype=torch.complex64),
        30.0,
        generator=torch.Generator().manual_seed(1),
    ).h
    for lag in (2, 5):
        dt = lag * ch.ofdm_symbol_duration_s
        measured = (h[:, lag:] * h[:, :-lag].conj()).mean().real / h.abs().pow(2).mean()
        theory = j0(2 * math.pi * 600.0 * dt)
        assert abs(float(measured) - theory) < 0.05, (lag, float(measured), theory)


def test_the_channels_page_states_every_channel_and_each_conditions_spread_and_doppler():
    from pathlib import Path

    page = (Path(__file__).resolve().parents[2] / "docs" / "channels.md").read_text()
    for name in phy.CHANNELS:
        if name not in CONDITIONS:
            assert f"`{name}`" in page, name
    for name in CONDITIONS:
        f = phy.CHANNELS[name]
        spread_ns = round(FIXED_TDL_PROFILES[f.profile] * 1e9)
        row = f"| `{name}` | TDL-{f.profile} | {spread_ns} ns |"
        assert row in page and f"| {f.max_doppler_hz:g} Hz |" in page.split(row)[1].split("\n")[0]
