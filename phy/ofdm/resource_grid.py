"""The OFDM resource grid: FFT size, cyclic prefix, guard and DC carriers, pilot pattern.

Subcarriers are indexed in *centred* order, as in sionna: index ``k`` of ``fft_size`` is
frequency ``(k - fft_size // 2) * subcarrier_spacing_hz``; the DC carrier is ``fft_size // 2``.
Pilots follow a Kronecker pattern: on every OFDM symbol in ``pilot_ofdm_symbols``, every
``pilot_subcarrier_spacing``-th used carrier (starting at the lowest) is a pilot; the last
used carrier is always a pilot too, so frequency interpolation never extrapolates. Pilot
values are unit-power QPSK from a fixed sequence, so transmitter and receiver agree.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

PILOT_SEED = 0x05E5F  # fixed: the pilot sequence is part of the waveform definition


@dataclass(frozen=True)
class ResourceGrid:
    """One OFDM slot.

    Attributes:
        fft_size: FFT size (number of subcarriers), in [8, 4096].
        cp_length: cyclic prefix in samples, in [0, fft_size].
        num_ofdm_symbols: OFDM symbols per slot, in [1, 100000].
        num_guard_carriers: (lower, upper) unused carriers at the band edges.
        dc_null: leave the DC carrier empty.
        pilot_ofdm_symbols: OFDM symbols (0-based) that carry pilots; must be non-empty
            for pilot-based estimation.
        pilot_subcarrier_spacing: pilot every this many used carriers on pilot symbols, >= 1.
        subcarrier_spacing_hz: carrier spacing (sets the sample rate ``fft_size * spacing``).
    """

    fft_size: int = 64
    cp_length: int = 16
    num_ofdm_symbols: int = 14
    num_guard_carriers: tuple[int, int] = (6, 5)
    dc_null: bool = True
    pilot_ofdm_symbols: tuple[int, ...] = (2, 11)
    pilot_subcarrier_spacing: int = 1
    subcarrier_spacing_hz: float = 15e3

    def __post_init__(self):
        if not isinstance(self.fft_size, int) or not 8 <= self.fft_size <= 4096:
            raise ValueError(f"fft_size must be an integer in [8, 4096], got {self.fft_size!r}")
        if not isinstance(self.cp_length, int) or not 0 <= self.cp_length <= self.fft_size:
            raise ValueError(
                f"cp_length must be an integer in [0, fft_size={self.fft_size}], got "
                f"{self.cp_length!r}"
            )
        if not isinstance(self.num_ofdm_symbols, int) or not 1 <= self.num_ofdm_symbols <= 100_000:
            raise ValueError(
                f"num_ofdm_symbols must be an integer in [1, 100000], got {self.num_ofdm_symbols!r}"
            )
        g = tuple(self.num_guard_carriers)
        if (
            len(g) != 2
            or any(not isinstance(v, int) or v < 0 for v in g)
            or sum(g) + 2 > self.fft_size
        ):
            raise ValueError(
                "num_guard_carriers must be two integers >= 0 leaving >= 2 used carriers, got "
                f"{self.num_guard_carriers!r}"
            )
        object.__setattr__(self, "num_guard_carriers", g)
        p = tuple(sorted(set(self.pilot_ofdm_symbols)))
        if any(not isinstance(v, int) or not 0 <= v < self.num_ofdm_symbols for v in p):
            raise ValueError(
                f"pilot_ofdm_symbols must be indices in [0, {self.num_ofdm_symbols - 1}], got "
                f"{self.pilot_ofdm_symbols!r}"
            )
        object.__setattr__(self, "pilot_ofdm_symbols", p)
        if not isinstance(self.pilot_subcarrier_spacing, int) or self.pilot_subcarrier_spacing < 1:
            raise ValueError(
                "pilot_subcarrier_spacing must be an integer >= 1, got "
                f"{self.pilot_subcarrier_spacing!r}"
            )
        if not math.isfinite(self.subcarrier_spacing_hz) or self.subcarrier_spacing_hz <= 0:
            raise ValueError(
                f"subcarrier_spacing_hz must be > 0, got {self.subcarrier_spacing_hz!r}"
            )
        if self.num_data_symbols < 1:
            raise ValueError("the pilot pattern leaves no data resource elements")

    # ---- derived values -------------------------------------------------------------
    @property
    def sample_rate_hz(self) -> float:
        return self.fft_size * self.subcarrier_spacing_hz

    @property
    def symbol_length(self) -> int:
        """Samples per OFDM symbol including the cyclic prefix."""
        return self.fft_size + self.cp_length

    @property
    def num_samples(self) -> int:
        """Time-domain samples of one slot."""
        return self.num_ofdm_symbols * self.symbol_length

    @functools.cached_property
    def used_subcarriers(self) -> np.ndarray:
        """Centred indices of the carriers that carry pilots or data, ascending."""
        lo, hi = self.num_guard_carriers
        k = np.arange(lo, self.fft_size - hi)
        if self.dc_null:
            k = k[k != self.fft_size // 2]
        return k

    @functools.cached_property
    def pilot_subcarriers(self) -> np.ndarray:
        used = self.used_subcarriers
        idx = np.unique(
            np.r_[np.arange(0, used.size, self.pilot_subcarrier_spacing), used.size - 1]
        )
        return used[idx]

    @property
    def subcarrier_frequencies_hz(self) -> np.ndarray:
        """[fft_size] baseband frequency of each centred carrier."""
        return (np.arange(self.fft_size) - self.fft_size // 2) * self.subcarrier_spacing_hz

    @functools.cached_property
    def pilot_mask(self) -> Tensor:
        """[num_ofdm_symbols, fft_size] bool."""
        m = torch.zeros(self.num_ofdm_symbols, self.fft_size, dtype=torch.bool)
        if self.pilot_ofdm_symbols:
            m[np.ix_(np.asarray(self.pilot_ofdm_symbols), self.pilot_subcarriers)] = True
        return m

    @functools.cached_property
    def data_mask(self) -> Tensor:
        """[num_ofdm_symbols, fft_size] bool: used carriers that are not pilots."""
        m = torch.zeros(self.num_ofdm_symbols, self.fft_size, dtype=torch.bool)
        m[:, self.used_subcarriers] = True
        return m & ~self.pilot_mask

    @functools.cached_property
    def data_index(self) -> Tensor:
        """[num_data_symbols] int64 positions of the data in the flattened grid (row-major)."""
        return torch.nonzero(self.data_mask.reshape(-1)).squeeze(1)

    @functools.cached_property
    def pilot_index(self) -> Tensor:
        """[num_pilots] int64 positions of the pilots in the flattened grid (row-major)."""
        return torch.nonzero(self.pilot_mask.reshape(-1)).squeeze(1)

    @functools.cached_property
    def num_data_symbols(self) -> int:
        """Data resource elements per slot."""
        used = self.used_subcarriers.size * self.num_ofdm_symbols
        pilots = len(self.pilot_ofdm_symbols) * self.pilot_subcarriers.size
        return used - pilots

    @functools.cached_property
    def pilots(self) -> Tensor:
        """[num_pilots] complex64 unit-power QPSK pilot values, row-major over the pilot mask."""
        n = int(self.pilot_mask.sum())
        rng = np.random.default_rng(PILOT_SEED)
        b = rng.integers(0, 2, size=(n, 2))
        return torch.tensor(
            ((1 - 2 * b[:, 0]) + 1j * (1 - 2 * b[:, 1])) / math.sqrt(2), dtype=torch.complex64
        )

    def num_slots(self, num_symbols: int) -> int:
        """Slots needed to carry ``num_symbols`` data symbols."""
        return max(1, -(-int(num_symbols) // self.num_data_symbols))


def map_to_grid(x: Tensor, grid: ResourceGrid) -> Tensor:
    """Place data symbols and pilots on the grid (zero on guard and DC carriers).

    Args:
        x: [batch, num_slots * grid.num_data_symbols] complex64 (pad with zeros first).
    Returns:
        [batch, num_slots * num_ofdm_symbols, fft_size] complex64; differentiable in x.
    """
    b, n = x.shape
    if n % grid.num_data_symbols:
        raise ValueError(
            f"x: num_symbols ({n}) must be a multiple of grid.num_data_symbols "
            f"({grid.num_data_symbols})"
        )
    slots = n // grid.num_data_symbols
    out = torch.zeros(
        b, slots, grid.num_ofdm_symbols, grid.fft_size, dtype=x.dtype, device=x.device
    )
    out[:, :, grid.data_mask.to(x.device)] = x.reshape(b, slots, grid.num_data_symbols)
    out[:, :, grid.pilot_mask.to(x.device)] = grid.pilots.to(x.device, x.dtype)
    return out.reshape(
        b, slots * grid.num_ofdm_symbols, grid.fft_size
    )  # [batch, num_ofdm_symbols, fft_size]


def extract_data(y: Tensor, grid: ResourceGrid) -> Tensor:
    """Inverse of :func:`map_to_grid`'s data placement.

    Args:
        y: [batch, num_slots * num_ofdm_symbols, fft_size] (any dtype).
    Returns:
        [batch, num_slots * num_data_symbols].
    """
    b, t, f = y.shape
    if f != grid.fft_size or t % grid.num_ofdm_symbols:
        raise ValueError(
            f"y must be [batch, k * {grid.num_ofdm_symbols}, {grid.fft_size}], got {tuple(y.shape)}"
        )
    slots = t // grid.num_ofdm_symbols
    y = y.reshape(b, slots, grid.num_ofdm_symbols * f)
    return y.index_select(-1, grid.data_index.to(y.device)).reshape(
        b, slots * grid.num_data_symbols
    )
