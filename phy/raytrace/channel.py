"""``RayTracedChannel``: the ray-traced CFR of each drone position on the Channel interface.

Symbols are frequency-domain: either OFDM-shaped ``[batch, num_ofdm_symbols, fft_size]``
(subcarrier ``k`` sees ``h[:, k]``, the same on every OFDM symbol) or flat
``[batch, num_symbols]`` (symbol ``i`` rides subcarrier ``i % num_subcarriers``, i.e. the
symbols fill OFDM symbols one after the other). Row ``b`` of the batch uses position ``b``;
a single position serves every row.

Gain normalisation:
* ``"per_position"`` (default): each position's CFR is scaled to unit mean ``|h|^2`` over
  the subcarriers, so ``snr_db`` is the mean received SNR and only the frequency
  selectivity of the ray-traced channel remains.
* ``"absolute"``: path loss is kept relative to ``reference_path_gain_db``: the received
  SNR is ``snr_db + path_gain_db - reference_path_gain_db``, so a drone that flies away
  fades. (The CFR is scaled by ``10**(-reference_path_gain_db / 20)``.)

In outage ``h = 0``: the receiver gets noise only, and ``outage`` says so (never NaN).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from phy.channels.base import Channel, ChannelOutput
from phy.conventions import snr_db_to_noise_var, validate_snr_db
from phy.raytrace.tracer import RayTracer, RayTracingConfig, check_frequencies, check_positions

GAIN_NORMALIZATIONS = ("per_position", "absolute")


class RayTracedChannel(Channel):
    """Fixed ray-traced channels of a batch of transmitter positions, plus AWGN.

    Args:
        scene: built-in scene name, ``.xml`` path or ``sionna.rt.Scene`` (ignored when
            ``tracer`` is given).
        rx_position_m: [3] ground-station position (metres).
        tx_positions_m: [num_positions, 3] drone positions (metres), e.g. a trajectory.
        carrier_frequency_hz: carrier (Hz).
        fft_size: subcarriers when ``subcarrier_frequencies_hz`` is not given, centred as in
            :class:`phy.ofdm.ResourceGrid`: ``(k - fft_size // 2) * subcarrier_spacing_hz``.
        subcarrier_spacing_hz: spacing for the default subcarriers (Hz).
        subcarrier_frequencies_hz: explicit [num_subcarriers] baseband frequencies (Hz).
        gain_normalization: ``"per_position"`` or ``"absolute"`` (module docstring).
        reference_path_gain_db: path gain that maps to ``snr_db`` with ``"absolute"``.
        config: :class:`RayTracingConfig` for the path solver.
        tracer: an existing :class:`RayTracer` (shares its scene and cache).
    """

    kind = "raytraced"
    h: Tensor  # registered buffers (see __init__)
    outage: Tensor

    def __init__(
        self,
        scene="simple_street_canyon",
        rx_position_m=(0.0, 0.0, 1.5),
        tx_positions_m=((20.0, 0.0, 30.0),),
        carrier_frequency_hz: float = 3.5e9,
        fft_size: int = 64,
        subcarrier_spacing_hz: float = 15e3,
        subcarrier_frequencies_hz=None,
        gain_normalization: str = "per_position",
        reference_path_gain_db: float | None = None,
        config: RayTracingConfig | None = None,
        tracer: RayTracer | None = None,
    ):
        super().__init__()
        if gain_normalization not in GAIN_NORMALIZATIONS:
            raise ValueError(
                f"gain_normalization must be one of {list(GAIN_NORMALIZATIONS)}, got {gain_normalization!r}"
            )
        if gain_normalization == "absolute":
            r = reference_path_gain_db
            if isinstance(r, bool) or not isinstance(r, int | float) or not math.isfinite(r):
                raise ValueError(
                    f"reference_path_gain_db must be a finite number (dB) with gain_normalization='absolute', got {r!r}"
                )
        if subcarrier_frequencies_hz is None:
            if (
                isinstance(fft_size, bool)
                or not isinstance(fft_size, int)
                or not 1 <= fft_size <= 65536
            ):
                raise ValueError(f"fft_size must be an integer in [1, 65536], got {fft_size!r}")
            s = subcarrier_spacing_hz
            if (
                isinstance(s, bool)
                or not isinstance(s, int | float)
                or not math.isfinite(s)
                or s <= 0
            ):
                raise ValueError(f"subcarrier_spacing_hz must be > 0 Hz, got {s!r}")
            subcarrier_frequencies_hz = (np.arange(fft_size) - fft_size // 2) * float(s)
        freqs = check_frequencies(subcarrier_frequencies_hz)
        positions = check_positions(tx_positions_m)
        self.tracer = tracer or RayTracer(scene, rx_position_m, carrier_frequency_hz, config)
        self.gain_normalization = gain_normalization
        self.reference_path_gain_db = reference_path_gain_db
        h, outage = self.tracer.cfr(positions, freqs)  # [num_positions, num_subcarriers]
        if gain_normalization == "per_position":
            p = h.abs().pow(2).mean(dim=1, keepdim=True)
            h = torch.where(p > 0, h / p.clamp_min(1e-300).sqrt(), torch.zeros_like(h))
        else:
            assert reference_path_gain_db is not None  # checked above for "absolute"
            h = h * 10.0 ** (-float(reference_path_gain_db) / 20.0)
        self.tx_positions_m = positions
        self.subcarrier_frequencies_hz = freqs
        self.register_buffer("h", h.to(torch.complex64), persistent=False)
        self.register_buffer("outage", outage, persistent=False)
        self.stats = self.tracer.stats(positions)

    @property
    def num_positions(self) -> int:
        return int(self.h.shape[0])

    @property
    def num_subcarriers(self) -> int:
        return int(self.h.shape[1])

    def channel_for(self, x: Tensor) -> tuple[Tensor, Tensor]:
        """h broadcastable to ``x`` and outage [batch] for ``x``'s batch (see module docs)."""
        if not isinstance(x, Tensor) or not x.is_complex():
            raise ValueError(
                f"x must be a complex64 tensor, got {getattr(x, 'dtype', type(x).__name__)}"
            )
        if x.dim() not in (2, 3):
            raise ValueError(
                f"x must be [batch, num_symbols] or [batch, num_ofdm_symbols, fft_size], got shape {tuple(x.shape)}"
            )
        batch = x.shape[0]
        if self.num_positions not in (1, batch):
            raise ValueError(
                f"x has batch {batch}, but the channel holds {self.num_positions} positions: "
                "batch must equal num_positions (or use one position)"
            )
        h = self.h.to(x.device).expand(batch, -1)
        outage = self.outage.to(x.device).expand(batch)
        if x.dim() == 3:
            if x.shape[2] != self.num_subcarriers:
                raise ValueError(
                    f"x has fft_size {x.shape[2]}, the channel has {self.num_subcarriers} subcarriers"
                )
            return h[:, None, :], outage
        idx = torch.arange(x.shape[1], device=x.device) % self.num_subcarriers
        return h[:, idx], outage

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> ChannelOutput:
        """Args: x [batch, num_symbols] or [batch, num_ofdm_symbols, fft_size] complex64;
        snr_db float or [batch] (Es/N0 at unit channel gain, dB).

        Returns: ChannelOutput with y like x, h broadcastable to y, noise_var [batch],
        outage [batch] bool.
        """
        h, outage = self.channel_for(x)
        validate_snr_db(snr_db)
        batch = x.shape[0]
        nv = snr_db_to_noise_var(torch.as_tensor(snr_db, dtype=torch.float32, device=x.device))
        nv = nv.reshape(-1).expand(batch) if nv.numel() in (1, batch) else None
        if nv is None:
            raise ValueError(f"snr_db must be a float or [batch={batch}] tensor")
        shape = (batch,) + (1,) * (x.dim() - 1)
        noise = torch.randn(x.shape, dtype=torch.complex64, generator=generator, device=x.device)
        y = h * x.to(torch.complex64) + noise * nv.reshape(shape).sqrt()
        return ChannelOutput(y=y, h=h, noise_var=nv.contiguous(), outage=outage)

    def extra_repr(self) -> str:
        return (
            f"num_positions={self.num_positions}, num_subcarriers={self.num_subcarriers}, "
            f"gain_normalization={self.gain_normalization!r}, tracer={self.tracer!r}"
        )


class PerPositionChannel(Channel):
    """A frequency-selective channel fixed by one position (its ray-traced CFR).

    Symbol ``k`` of a block rides subcarrier ``k mod num_subcarriers``; the CFR is normalised
    to unit mean power, so ``snr_db`` is the received SNR of this position.

    Args:
        h: [num_subcarriers] complex64 frequency response.
    """

    kind = "raytraced"
    h: Tensor  # registered buffer

    def __init__(self, h):
        super().__init__()
        h = torch.as_tensor(np.asarray(h, np.complex64))
        p = float((h.abs() ** 2).mean())
        self.register_buffer("h", h / math.sqrt(p) if p > 0 else h)

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> ChannelOutput:
        validate_snr_db(snr_db)
        n = x.shape[-1]
        hk = self.h[torch.arange(n) % self.h.numel()].expand(x.shape[0], n)  # [batch, num_symbols]
        nv = float(snr_db_to_noise_var(float(snr_db)))
        noise = torch.complex(
            torch.randn(x.shape, generator=generator), torch.randn(x.shape, generator=generator)
        )
        y = hk * x + noise.to(torch.complex64) * math.sqrt(nv / 2)
        return ChannelOutput(
            y, hk, torch.full((x.shape[0],), nv), torch.zeros(x.shape[0], dtype=torch.bool)
        )
