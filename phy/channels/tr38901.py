"""3GPP TR 38.901 TDL and CDL multipath channels through sionna.phy, in the frequency domain.

The channel acts on OFDM resource grids ``[batch, num_ofdm_symbols, fft_size]`` (centred
carrier order) as one complex gain per resource element, ``y = H x + n``, with H from
sionna's ``TDL``/``CDL`` power-delay profiles (single antenna each side) converted by
``cir_to_ofdm_channel`` at the carrier frequencies and sampled once per OFDM symbol. This
is exact for an OFDM receiver whose cyclic prefix is longer than the delay spread.
A 2-D input ``[batch, num_symbols]`` is laid out row by row on ``fft_size`` carriers.

The TR 38.901 version of the parameter tables is pinned (``spec_version``, default
:data:`SPEC_VERSION`, never sionna's default, which sionna 2.1 moved to V19.2) and every
channel says it in :meth:`record`. TDL also takes the fixed-delay profiles of TS 38.101-4
Annex B.2.1 (``"A10"`` .. ``"D30"``: absolute tap delays, their own delay spread); its
``max_doppler_hz`` sets the terminal speed that gives a maximum Doppler frequency, as the
standard's propagation conditions name it (``TDLA30-10``: TDL-A30 at 10 Hz).

sionna draws from its global ``sionna.phy.config`` generator; during each call that
generator is swapped for the caller's ``torch.Generator`` (and restored), so draws are
reproducible per call and the global state is left untouched.
"""

from __future__ import annotations

import contextlib
import math

import torch
from torch import Tensor

from common import Registry
from phy.channels._common import add_noise, check_symbols, noise_var_per_batch
from phy.channels.base import Channel, ChannelOutput
from phy.conventions import SPEED_OF_LIGHT_M_S

SPEC_VERSIONS = ("16.1", "19.2")
"""TR 38.901 versions whose parameter tables sionna 2.2 ships (its ``spec_version``)."""
SPEC_VERSION = "19.2"
"""The pinned TR 38.901 version of the TDL/CDL tables: what every result states."""
FIXED_TDL_PROFILES = Registry[float](
    "TS 38.101-4 delay profile",
    {
        "A10": 10e-9,
        "A30": 30e-9,
        "B100": 100e-9,
        "C60": 60e-9,
        "C300": 300e-9,
        "D10": 10e-9,
        "D30": 30e-9,
    },
)
"""TS 38.101-4 V19.2.2 Annex B.2.1 fixed-delay TDL profiles -> their RMS delay spread (s).
D10 and D30 have a line-of-sight tap (Rician first tap); the others are Rayleigh taps."""
SCALABLE_MODELS = ("A", "B", "C", "D", "E")
TDL_MODELS = (*SCALABLE_MODELS, *FIXED_TDL_PROFILES)
CDL_MODELS = SCALABLE_MODELS
DEFAULT_DELAY_SPREAD_S = 100e-9
"""Delay spread of a scalable profile when none is given (TR 38.901's nominal 100 ns)."""


@contextlib.contextmanager
def sionna_generator(generator: torch.Generator | None, device: str = "cpu"):
    """Make sionna.phy draw from ``generator`` inside the block (no-op for None)."""
    from sionna.phy import config

    if generator is None:
        yield
        return
    rngs = config._torch_rngs  # noqa: SLF001 - sionna keeps one generator per device here
    if device not in rngs:
        config.torch_rng(device)
    saved = rngs[device]
    rngs[device] = generator
    try:
        yield
    finally:
        rngs[device] = saved


def _check_positive(name: str, value, low: float, high: float) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or not low <= value <= high
    ):
        raise ValueError(f"{name} must be a number in [{low:g}, {high:g}], got {value!r}")
    return float(value)


def check_spec_version(spec_version) -> str:
    """``spec_version`` if it is one of :data:`SPEC_VERSIONS`, else a one-line ValueError."""
    if not isinstance(spec_version, str) or spec_version not in SPEC_VERSIONS:
        raise ValueError(
            f"spec_version must be one of {', '.join(SPEC_VERSIONS)} (TR 38.901 version), "
            f"got {spec_version!r}"
        )
    return spec_version


def _delay_spread(model: str, delay_spread_s) -> float:
    """The profile's fixed spread for a TS 38.101-4 model (a different value is refused);
    the given one (default :data:`DEFAULT_DELAY_SPREAD_S`) for a scalable model."""
    if model in FIXED_TDL_PROFILES:
        fixed = FIXED_TDL_PROFILES[model]
        if delay_spread_s is not None and not math.isclose(delay_spread_s, fixed, rel_tol=1e-6):
            raise ValueError(
                f"delay_spread_s must be {fixed:g} (or left out) for the fixed TS 38.101-4 "
                f"profile {model}, got {delay_spread_s!r}"
            )
        return fixed
    spread = DEFAULT_DELAY_SPREAD_S if delay_spread_s is None else delay_spread_s
    return _check_positive("delay_spread_s", spread, 1e-9, 1e-5)


class _TR38901Channel(Channel):
    """Shared frequency-domain application; subclasses build the sionna model."""

    MODELS: tuple[str, ...] = ()
    FAMILY = ""
    kind: str = ""  # each subclass's phy.CHANNELS name; a named condition sets its own

    def __init__(
        self,
        model: str = "A",
        delay_spread_s: float | None = None,
        carrier_frequency_hz: float = 3.5e9,
        subcarrier_spacing_hz: float = 15e3,
        fft_size: int = 64,
        cp_length: int = 16,
        min_speed_m_s: float = 0.0,
        max_speed_m_s: float | None = None,
        max_doppler_hz: float | None = None,
        spec_version: str = SPEC_VERSION,
        kind: str | None = None,
    ):
        super().__init__()
        if model not in self.MODELS:
            raise ValueError(f"model must be one of {list(self.MODELS)}, got {model!r}")
        self.model = model
        self.spec_version = check_spec_version(spec_version)
        if kind is not None:
            self.kind = kind  # the phy.CHANNELS name of a named condition
        self.delay_spread_s = _delay_spread(model, delay_spread_s)
        self.carrier_frequency_hz = _check_positive(
            "carrier_frequency_hz", carrier_frequency_hz, 1e8, 1e11
        )
        self.subcarrier_spacing_hz = _check_positive(
            "subcarrier_spacing_hz", subcarrier_spacing_hz, 1e2, 1e7
        )
        if not isinstance(fft_size, int) or not 8 <= fft_size <= 4096:
            raise ValueError(f"fft_size must be an integer in [8, 4096], got {fft_size!r}")
        if not isinstance(cp_length, int) or not 0 <= cp_length <= fft_size:
            raise ValueError(f"cp_length must be an integer in [0, {fft_size}], got {cp_length!r}")
        self.fft_size = fft_size
        self.cp_length = cp_length
        if max_doppler_hz is not None:
            if min_speed_m_s != 0.0 or max_speed_m_s is not None:
                raise ValueError(
                    "max_doppler_hz sets the speed: give it or min_speed_m_s/max_speed_m_s, "
                    "not both"
                )
            fd = _check_positive("max_doppler_hz", max_doppler_hz, 0.0, 1e5)
            self.min_speed_m_s = self.max_speed_m_s = fd * SPEED_OF_LIGHT_M_S / carrier_frequency_hz
        else:
            self.min_speed_m_s = _check_positive("min_speed_m_s", min_speed_m_s, 0.0, 500.0)
            hi = self.min_speed_m_s if max_speed_m_s is None else max_speed_m_s
            self.max_speed_m_s = _check_positive("max_speed_m_s", hi, self.min_speed_m_s, 500.0)
        self._sionna_model = None

    @property
    def max_doppler_hz(self) -> float:
        """Maximum Doppler frequency at ``max_speed_m_s``: ``v f_c / c``."""
        return self.max_speed_m_s * self.carrier_frequency_hz / SPEED_OF_LIGHT_M_S

    @property
    def standard(self) -> str:
        """Where the profile's table comes from, with its version."""
        if self.model in FIXED_TDL_PROFILES:
            return "3GPP TS 38.101-4 V19.2.2 Annex B.2.1 (fixed delays)"
        return f"3GPP TR 38.901 V{self.spec_version}"

    def record(self) -> dict:
        """What a result records of this channel (JSON): name, profile, its source and the
        pinned TR 38.901 ``spec_version``, delay spread, carrier, speeds, Doppler, numerology."""
        return {
            "channel": self.kind,
            "model": f"{self.FAMILY}-{self.model}",
            "standard": self.standard,
            "spec_version": self.spec_version,
            "delay_spread_s": self.delay_spread_s,
            "carrier_frequency_hz": self.carrier_frequency_hz,
            "min_speed_m_s": self.min_speed_m_s,
            "max_speed_m_s": self.max_speed_m_s,
            "max_doppler_hz": self.max_doppler_hz,
            "subcarrier_spacing_hz": self.subcarrier_spacing_hz,
            "fft_size": self.fft_size,
            "cp_length": self.cp_length,
            "antennas": "SISO",
            "sampled": "once per OFDM symbol (frequency domain)",
        }

    @property
    def ofdm_symbol_duration_s(self) -> float:
        return (self.fft_size + self.cp_length) / (self.fft_size * self.subcarrier_spacing_hz)

    def _build(self):  # pragma: no cover - overridden
        raise NotImplementedError

    def _model(self):
        if self._sionna_model is None:
            self._sionna_model = self._build()
        return self._sionna_model

    def frequency_response(self, batch: int, num_ofdm_symbols: int, generator=None) -> Tensor:
        """[batch, num_ofdm_symbols, fft_size] complex64 channel per resource element, E|H|^2 =
        1."""
        from sionna.phy.channel import cir_to_ofdm_channel, subcarrier_frequencies

        with sionna_generator(generator):
            a, tau = self._model()(batch, num_ofdm_symbols, 1.0 / self.ofdm_symbol_duration_s)
        freqs = subcarrier_frequencies(
            self.fft_size, self.subcarrier_spacing_hz, precision="single", device="cpu"
        )
        h = cir_to_ofdm_channel(
            freqs, a, tau, normalize=False
        )  # [batch, 1, 1, 1, 1, time, fft_size]
        return h.reshape(batch, num_ofdm_symbols, self.fft_size).to(torch.complex64)

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> ChannelOutput:
        """Args: x [batch, num_ofdm_symbols, fft_size] or [batch, num_symbols] complex64.

        Returns: y like x; h like x (per resource element); noise_var [batch].
        """
        check_symbols(x)
        nv = noise_var_per_batch(snr_db, x.shape[0], x.device)
        flat = x.dim() == 2
        if flat:
            n = x.shape[1]
            rows = -(-n // self.fft_size)
            g = torch.nn.functional.pad(x, (0, rows * self.fft_size - n)).reshape(
                x.shape[0], rows, self.fft_size
            )
        elif x.dim() == 3 and x.shape[-1] == self.fft_size:
            g = x
        else:
            raise ValueError(
                f"x must be [batch, num_symbols] or [batch, num_ofdm_symbols, {self.fft_size}], "
                f"got {tuple(x.shape)}"
            )
        h = self.frequency_response(g.shape[0], g.shape[1], generator).to(x.device, x.dtype)
        y = add_noise(h * g, nv, generator)
        if flat:
            y = y.reshape(x.shape[0], -1)[:, : x.shape[1]]
            h = h.reshape(x.shape[0], -1)[:, : x.shape[1]]
        return ChannelOutput(y=y, h=h, noise_var=nv, outage=None)

    def extra_repr(self) -> str:
        return (
            f"model={self.model!r}, delay_spread_s={self.delay_spread_s:g}, "
            f"carrier_frequency_hz={self.carrier_frequency_hz:g}, fft_size={self.fft_size}, "
            f"subcarrier_spacing_hz={self.subcarrier_spacing_hz:g}, "
            f"max_doppler_hz={self.max_doppler_hz:g}, spec_version={self.spec_version!r}"
        )


class TDLChannel(_TR38901Channel):
    """3GPP TDL-A..E (A-C non-line-of-sight, D-E line-of-sight) and the TS 38.101-4 fixed
    profiles, single antenna.

    Args:
        model: "A".."E" (TR 38.901, scaled to ``delay_spread_s``) or a fixed TS 38.101-4
            profile of :data:`FIXED_TDL_PROFILES` ("A10", "A30", "B100", "C60", "C300",
            "D10", "D30").
        delay_spread_s: RMS delay spread the scalable profile is scaled to, in [1 ns, 10 us]
            (default 100 ns); a fixed profile has its own (leave it out).
        carrier_frequency_hz: in [100 MHz, 100 GHz].
        subcarrier_spacing_hz, fft_size, cp_length: the OFDM numerology the channel is sampled on.
        min_speed_m_s, max_speed_m_s: terminal speed range (Doppler); equal by default.
        max_doppler_hz: instead of the speeds, the maximum Doppler frequency in [0, 100 kHz]
            (speed ``f_D c / f_c``, one speed for every draw).
        spec_version: TR 38.901 version of the tables, one of :data:`SPEC_VERSIONS`
            (default :data:`SPEC_VERSION`, pinned); the fixed profiles do not depend on it.
        kind: the ``phy.CHANNELS`` name it is registered under (default "tdl").
    """

    MODELS = TDL_MODELS
    FAMILY = "TDL"

    kind = "tdl"

    def _build(self):
        from sionna.phy.channel.tr38901 import TDL

        fixed = self.model in FIXED_TDL_PROFILES  # sionna takes the profile's own spread
        return TDL(
            self.model,
            None if fixed else self.delay_spread_s,
            self.carrier_frequency_hz,
            min_speed=self.min_speed_m_s,
            max_speed=self.max_speed_m_s,
            precision="single",
            device="cpu",
            spec_version=self.spec_version,
        )

    @property
    def power_delay_profile(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(delays_s [num_paths], mean_powers [num_paths]) of the scaled 3GPP profile."""
        m = self._model()
        return m.delays.detach().float().cpu(), m.mean_powers.detach().float().cpu()


class CDLChannel(_TR38901Channel):
    """3GPP CDL-A..E between single omnidirectional vertically polarised antennas (uplink:
    drone = UT transmits to the ground station = BS). Same arguments as :class:`TDLChannel`;
    ``model`` is "A".."E" (CDL has no fixed TS 38.101-4 profiles).
    """

    MODELS = CDL_MODELS
    FAMILY = "CDL"

    kind = "cdl"

    def _build(self):
        from sionna.phy.channel.tr38901 import CDL, Antenna

        def ant():
            return Antenna(
                "single", "V", "omni", self.carrier_frequency_hz, precision="single", device="cpu"
            )

        return CDL(
            self.model,
            self.delay_spread_s,
            self.carrier_frequency_hz,
            ut_array=ant(),
            bs_array=ant(),
            direction="uplink",
            min_speed=self.min_speed_m_s,
            max_speed=self.max_speed_m_s,
            precision="single",
            device="cpu",
            spec_version=self.spec_version,
        )
