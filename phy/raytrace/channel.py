"""``RayTracedChannel``: the ray-traced CFR of each drone position on the Channel interface.

Symbols are frequency-domain: either OFDM-shaped ``[batch, num_ofdm_symbols, fft_size]``
(subcarrier ``k`` sees ``h[:, k]``, the same on every OFDM symbol) or flat
``[batch, num_symbols]`` (symbol ``i`` rides subcarrier ``i % num_subcarriers``, i.e. the
symbols fill OFDM symbols one after the other). Row ``b`` of the batch uses position ``b``;
a single position serves every row.

A moving drone (``tx_velocities_m_s``, and ``ofdm_symbol_duration_s``) changes the channel
over the transmission with each path's Doppler shift (:mod:`phy.raytrace.mobility`), which
starts at the drone's position at t = 0: OFDM symbol ``l`` of a grid is sent at
``l * ofdm_symbol_duration_s``; flat symbol ``i`` at ``i * ofdm_symbol_duration_s /
num_subcarriers`` (in time order, filling the OFDM symbols). At rest it is the fixed
response above, exactly. :class:`PerPositionChannel` is the same for one position, with its
own symbol duration.

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
from phy.raytrace.mobility import MovingTransmitter, flat_symbol_times
from phy.raytrace.tracer import RayTracer, RayTracingConfig, check_frequencies, check_positions

GAIN_NORMALIZATIONS = ("per_position", "absolute")


def _check_duration(v, name: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be > 0 seconds for a moving transmitter, got {v!r}")
    return float(v)


def _movers(tracer: RayTracer, positions: np.ndarray, velocities) -> list[MovingTransmitter]:
    """One mover per position ([] when nothing moves)."""
    if velocities is None:
        return []
    v = check_positions(velocities, "tx_velocities_m_s", "m/s")
    if v.shape[0] not in (1, len(positions)):
        raise ValueError(
            f"tx_velocities_m_s must be [3] or [num_positions={len(positions)}, 3], got shape "
            f"{v.shape}"
        )
    v = np.broadcast_to(v, positions.shape)
    if not v.any():
        return []
    tracer.cir(positions, v)  # trace every position in one solver call
    return [MovingTransmitter(tracer, p, vi) for p, vi in zip(positions, v)]


class RayTracedChannel(Channel):
    """Ray-traced channels of a batch of transmitter positions, at rest or moving, plus AWGN.

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
        tx_velocities_m_s: [num_positions, 3] or [3] drone velocities (m/s); None or all
            zero: at rest.
        ofdm_symbol_duration_s: time between OFDM symbols, cyclic prefix included (> 0),
            needed for a moving drone (module docstring).
    """

    kind = "raytraced"
    h: Tensor  # registered buffers (see __init__): the response at t = 0
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
        tx_velocities_m_s=None,
        ofdm_symbol_duration_s: float | None = None,
    ):
        super().__init__()
        if gain_normalization not in GAIN_NORMALIZATIONS:
            raise ValueError(
                f"gain_normalization must be one of {list(GAIN_NORMALIZATIONS)}, got "
                f"{gain_normalization!r}"
            )
        if gain_normalization == "absolute":
            r = reference_path_gain_db
            if isinstance(r, bool) or not isinstance(r, int | float) or not math.isfinite(r):
                raise ValueError(
                    "reference_path_gain_db must be a finite number (dB) with "
                    f"gain_normalization='absolute', got {r!r}"
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
        self.movers = _movers(self.tracer, positions, tx_velocities_m_s)
        if self.movers:
            self.ofdm_symbol_duration_s = _check_duration(
                ofdm_symbol_duration_s, "ofdm_symbol_duration_s"
            )
            h0 = np.stack([m.response([0.0], freqs)[0] for m in self.movers])
            h = torch.from_numpy(h0.astype(np.complex64))
            outage = torch.from_numpy(~(np.abs(h0) > 0).any(axis=1))
        else:
            h, outage = self.tracer.cfr(positions, freqs)  # [num_positions, num_subcarriers]
        if gain_normalization == "per_position":
            p = h.abs().pow(2).mean(dim=1, keepdim=True)
            h = torch.where(p > 0, h / p.clamp_min(1e-300).sqrt(), torch.zeros_like(h))
            p64 = p.numpy().astype(np.float64)
            scale = np.where(p64 > 0, 1 / np.sqrt(np.maximum(p64, 1e-300)), 0.0)
        else:
            assert reference_path_gain_db is not None  # checked above for "absolute"
            h = h * 10.0 ** (-float(reference_path_gain_db) / 20.0)
            scale = np.full((len(h), 1), 10.0 ** (-float(reference_path_gain_db) / 20.0))
        self.scale = scale  # [num_positions, 1] float64, applied to the moving response
        self.tx_positions_m = positions
        self.subcarrier_frequencies_hz = freqs
        self.register_buffer("h", h.to(torch.complex64), persistent=False)
        self.register_buffer("outage", outage, persistent=False)
        self.stats = self.tracer.stats(positions, tx_velocities_m_s if self.movers else None)

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
                "x must be [batch, num_symbols] or [batch, num_ofdm_symbols, fft_size], got shape "
                f"{tuple(x.shape)}"
            )
        batch = x.shape[0]
        if self.num_positions not in (1, batch):
            raise ValueError(
                f"x has batch {batch}, but the channel holds {self.num_positions} positions: "
                "batch must equal num_positions (or use one position)"
            )
        outage = self.outage.to(x.device).expand(batch)
        if x.dim() == 3 and x.shape[2] != self.num_subcarriers:
            raise ValueError(
                f"x has fft_size {x.shape[2]}, the channel has {self.num_subcarriers} subcarriers"
            )
        if self.movers:
            return self._moving_channel(x).expand(batch, *x.shape[1:]), outage
        h = self.h.to(x.device).expand(batch, -1)
        if x.dim() == 3:
            return h[:, None, :], outage
        idx = torch.arange(x.shape[1], device=x.device) % self.num_subcarriers
        return h[:, idx], outage

    def _moving_channel(self, x: Tensor) -> Tensor:
        """[num_positions, *x.shape[1:]] complex64: each position's response over time."""
        f, t_sym = self.subcarrier_frequencies_hz, self.ofdm_symbol_duration_s
        if x.dim() == 3:
            rows, cols = np.arange(x.shape[1]) * t_sym, None
        else:
            rows, cols = flat_symbol_times(x.shape[1], f.size, t_sym / f.size)
        hn = np.stack([m.response(rows, f, cols) for m in self.movers]) * self.scale[:, :, None]
        h = torch.from_numpy(hn.astype(np.complex64)).to(x.device)  # [num_positions, rows, F]
        if x.dim() == 2:
            h = h.reshape(len(self.movers), -1)[:, : x.shape[1]]  # [num_positions, num_symbols]
        return h

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

    Flat blocks ``[batch, num_symbols]``: symbol ``k`` of a block rides subcarrier
    ``k mod num_subcarriers``. OFDM grids ``[batch, num_ofdm_symbols, num_subcarriers]``:
    subcarrier ``k`` sees ``h[k]``. The CFR is normalised to unit mean power at t = 0, so
    ``snr_db`` is the received SNR of this position.

    With a ``mover`` the drone flies on while it sends, and the rows of a batch (the copies
    of a block, a receiver's pilot blocks) are sent one after the other from t = 0, so
    later rows see the channel further along the flight: flat symbol ``k`` of row ``b`` at
    ``(b * num_symbols + k) * symbol_duration_s``, OFDM symbol ``l`` of row ``b`` at
    ``(b * num_ofdm_symbols + l) * ofdm_symbol_duration_s``, each at the response of that
    time (the same normalisation). At rest every row sees the same response.

    Args:
        h: [num_subcarriers] complex64 frequency response.
        mover: the moving drone (:class:`phy.raytrace.MovingTransmitter`, or anything with
            ``speed_m_s`` and its ``response``), or None (at rest).
        subcarrier_frequencies_hz: [num_subcarriers] offsets of ``h``'s subcarriers (with
            ``mover``).
        symbol_duration_s: time between successive flat symbols (with ``mover``), > 0.
        ofdm_symbol_duration_s: time between OFDM symbols, cyclic prefix included (with
            ``mover``, for grids), > 0; None: grids are refused while moving.
    """

    kind = "raytraced"
    h: Tensor  # registered buffer

    def __init__(
        self,
        h,
        mover: MovingTransmitter | None = None,
        subcarrier_frequencies_hz=None,
        symbol_duration_s: float | None = None,
        ofdm_symbol_duration_s: float | None = None,
    ):
        super().__init__()
        h = torch.as_tensor(np.asarray(h, np.complex64))
        p = float((h.abs() ** 2).mean())
        self.register_buffer("h", h / math.sqrt(p) if p > 0 else h)
        self.mover = mover if mover is not None and mover.speed_m_s > 0 else None
        self.ofdm_symbol_duration_s: float | None = None
        if self.mover is not None:
            self.symbol_duration_s = _check_duration(symbol_duration_s, "symbol_duration_s")
            if ofdm_symbol_duration_s is not None:
                self.ofdm_symbol_duration_s = _check_duration(
                    ofdm_symbol_duration_s, "ofdm_symbol_duration_s"
                )
            self.freqs = check_frequencies(subcarrier_frequencies_hz)
            if self.freqs.size != h.numel():
                raise ValueError(
                    f"subcarrier_frequencies_hz has {self.freqs.size} entries, h has {h.numel()}"
                )
            self.scale = 1 / math.sqrt(p) if p > 0 else 1.0

    def response(self, num_symbols: int, num_blocks: int | None = None) -> Tensor:
        """The (normalised) channel of each symbol of a flat block: [num_symbols] complex64
        for one block, or [num_blocks, num_symbols] for ``num_blocks`` blocks sent one
        after the other."""
        n = self.h.numel()
        blocks = 1 if num_blocks is None else int(num_blocks)
        if self.mover is None:
            h = self.h[torch.arange(num_symbols) % n]
            return h if num_blocks is None else h.expand(blocks, num_symbols)
        total = blocks * int(num_symbols)
        rows, cols = flat_symbol_times(total, n, self.symbol_duration_s)
        hn = self.mover.response(rows, self.freqs, cols).reshape(-1)[:total] * self.scale
        h = torch.from_numpy(hn.astype(np.complex64))
        return h if num_blocks is None else h.reshape(blocks, num_symbols)

    def grid_response(self, num_ofdm_symbols: int, num_blocks: int = 1) -> Tensor:
        """[num_blocks, num_ofdm_symbols, num_subcarriers] complex64: the (normalised)
        channel of each resource element of ``num_blocks`` grids sent one after the other."""
        if self.mover is None:
            return self.h.expand(num_blocks, num_ofdm_symbols, -1)
        if self.ofdm_symbol_duration_s is None:
            raise ValueError("a moving PerPositionChannel needs ofdm_symbol_duration_s for grids")
        rows = np.arange(num_blocks * num_ofdm_symbols) * self.ofdm_symbol_duration_s
        hn = self.mover.response(rows, self.freqs) * self.scale
        return torch.from_numpy(hn.astype(np.complex64)).reshape(num_blocks, num_ofdm_symbols, -1)

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> ChannelOutput:
        """Args: x [batch, num_symbols] or [batch, num_ofdm_symbols, num_subcarriers]
        complex64; snr_db float (Es/N0 at unit channel gain, dB).

        Returns: ChannelOutput with y and h like x, noise_var [batch], outage [batch] (False).
        """
        validate_snr_db(snr_db)
        if x.dim() == 3:
            if x.shape[2] != self.h.numel():
                raise ValueError(
                    f"x has {x.shape[2]} subcarriers, the channel has {self.h.numel()}"
                )
            hk = self.grid_response(x.shape[1], x.shape[0])
        elif self.mover is None:
            n = x.shape[-1]
            hk = self.response(n).expand(x.shape[0], n)  # [batch, num_symbols]
        else:
            hk = self.response(x.shape[-1], x.shape[0])  # [batch, num_symbols]
        nv = float(snr_db_to_noise_var(float(snr_db)))
        noise = torch.complex(
            torch.randn(x.shape, generator=generator), torch.randn(x.shape, generator=generator)
        )
        y = hk * x + noise.to(torch.complex64) * math.sqrt(nv / 2)
        return ChannelOutput(
            y, hk, torch.full((x.shape[0],), nv), torch.zeros(x.shape[0], dtype=torch.bool)
        )
