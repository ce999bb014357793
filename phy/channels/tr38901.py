"""3GPP TR 38.901 TDL and CDL multipath channels through sionna.phy, in the frequency domain.

The channel acts on OFDM resource grids ``[batch, num_ofdm_symbols, fft_size]`` (centred
carrier order) as one complex gain per resource element, ``y = H x + n``, with H from
sionna's ``TDL``/``CDL`` power-delay profiles (single antenna each side) converted by
``cir_to_ofdm_channel`` at the carrier frequencies and sampled once per OFDM symbol. This
is exact for an OFDM receiver whose cyclic prefix is longer than the delay spread.
A 2-D input ``[batch, num_symbols]`` is laid out row by row on ``fft_size`` carriers.

sionna draws from its global ``sionna.phy.config`` generator; during each call that
generator is swapped for the caller's ``torch.Generator`` (and restored), so draws are
reproducible per call and the global state is left untouched.
"""

from __future__ import annotations

import contextlib
import math

import torch
from torch import Tensor

from phy.channels._common import add_noise, check_symbols, noise_var_per_batch
from phy.channels.base import Channel, ChannelOutput

TDL_MODELS = ("A", "B", "C", "D", "E")
CDL_MODELS = ("A", "B", "C", "D", "E")


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
    if not isinstance(value, int | float) or not math.isfinite(value) or not low <= value <= high:
        raise ValueError(f"{name} must be a number in [{low:g}, {high:g}], got {value!r}")
    return float(value)


class _TR38901Channel(Channel):
    """Shared frequency-domain application; subclasses build the sionna model."""

    MODELS: tuple[str, ...] = ()

    def __init__(
        self,
        model: str = "A",
        delay_spread_s: float = 100e-9,
        carrier_frequency_hz: float = 3.5e9,
        subcarrier_spacing_hz: float = 15e3,
        fft_size: int = 64,
        cp_length: int = 16,
        min_speed_m_s: float = 0.0,
        max_speed_m_s: float | None = None,
    ):
        super().__init__()
        if model not in self.MODELS:
            raise ValueError(f"model must be one of {list(self.MODELS)}, got {model!r}")
        self.model = model
        self.delay_spread_s = _check_positive("delay_spread_s", delay_spread_s, 1e-9, 1e-5)
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
        self.min_speed_m_s = _check_positive("min_speed_m_s", min_speed_m_s, 0.0, 500.0)
        hi = self.min_speed_m_s if max_speed_m_s is None else max_speed_m_s
        self.max_speed_m_s = _check_positive("max_speed_m_s", hi, self.min_speed_m_s, 500.0)
        self._sionna_model = None

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
        """[batch, num_ofdm_symbols, fft_size] complex64 channel per resource element, E|H|^2 = 1."""
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
                f"x must be [batch, num_symbols] or [batch, num_ofdm_symbols, {self.fft_size}], got {tuple(x.shape)}"
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
            f"subcarrier_spacing_hz={self.subcarrier_spacing_hz:g}"
        )


class TDLChannel(_TR38901Channel):
    """3GPP TDL-A..E (A-C non-line-of-sight, D-E line-of-sight), single antenna.

    Args:
        model: "A".."E".
        delay_spread_s: RMS delay spread the profile is scaled to, in [1 ns, 10 us].
        carrier_frequency_hz: in [100 MHz, 100 GHz].
        subcarrier_spacing_hz, fft_size, cp_length: the OFDM numerology the channel is sampled on.
        min_speed_m_s, max_speed_m_s: terminal speed range (Doppler); equal by default.
    """

    MODELS = TDL_MODELS

    kind = "tdl"

    def _build(self):
        from sionna.phy.channel.tr38901 import TDL

        return TDL(
            self.model,
            self.delay_spread_s,
            self.carrier_frequency_hz,
            min_speed=self.min_speed_m_s,
            max_speed=self.max_speed_m_s,
            precision="single",
            device="cpu",
        )

    @property
    def power_delay_profile(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(delays_s [num_paths], mean_powers [num_paths]) of the scaled 3GPP profile."""
        m = self._model()
        return m.delays.detach().float().cpu(), m.mean_powers.detach().float().cpu()


class CDLChannel(_TR38901Channel):
    """3GPP CDL-A..E between single omnidirectional vertically polarised antennas (uplink:
    drone = UT transmits to the ground station = BS). Same arguments as :class:`TDLChannel`.
    """

    MODELS = CDL_MODELS

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
        )
