"""LMMSE channel estimation on the pilots: sionna's ``LMMSEChannelEstimator`` on our grid.

The receiver filters its LS pilot estimates across subcarriers, then across OFDM symbols
(``order="f-t"``), with the covariances of a statistical channel model it assumes, not
the one it is given:

* frequency: TR 38.901 TDL-A at ``delay_spread_s`` (``sionna.phy.ofdm.tdl_freq_cov_mat``);
* time: Jakes, ``J0(2 pi f_d dt)`` for a transmitter at ``speed_m_s`` on
  ``carrier_frequency_hz`` (``sionna.phy.ofdm.tdl_time_cov_mat``, TDL-A is NLoS).

Unlike linear interpolation it weighs pilots by how much the channel is expected to have
changed since, and reports its own error variance from that model. The grid's slots are
estimated one by one (no pilot of the next slot is used). The model assumes a unit-power
channel (``E|h|^2 = 1``, as a per-position normalised ray-traced channel has).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from phy.ofdm.resource_grid import ResourceGrid


class LMMSEEstimator:
    """``estimator(y, noise_var) -> (h_hat, error_var)``, like :func:`ls_channel_estimate`.

    Args:
        grid: the :class:`ResourceGrid` (pilots on ``pilot_ofdm_symbols``).
        speed_m_s: transmitter speed the time covariance assumes (>= 0).
        carrier_frequency_hz: carrier (> 0).
        delay_spread_s: RMS delay spread the frequency covariance assumes (> 0).
    """

    def __init__(
        self,
        grid: ResourceGrid,
        speed_m_s: float,
        carrier_frequency_hz: float,
        delay_spread_s: float = 100e-9,
    ):
        from sionna.phy.ofdm import (
            LMMSEChannelEstimator,
            PilotPattern,
            tdl_freq_cov_mat,
            tdl_time_cov_mat,
        )
        from sionna.phy.ofdm import ResourceGrid as SionnaGrid

        for name, v, low in (
            ("speed_m_s", speed_m_s, 0.0),
            ("carrier_frequency_hz", carrier_frequency_hz, 1.0),
            ("delay_spread_s", delay_spread_s, 1e-12),
        ):
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number >= {low:g}, got {v!r}")
            if v < low:
                raise ValueError(f"{name} must be a finite number >= {low:g}, got {v!r}")
        if not grid.pilot_ofdm_symbols:
            raise ValueError("grid has no pilot_ofdm_symbols: pilot-based estimation needs pilots")
        self.grid = grid
        self.speed_m_s = float(speed_m_s)
        self.carrier_frequency_hz = float(carrier_frequency_hz)
        self.delay_spread_s = float(delay_spread_s)
        used = grid.used_subcarriers
        mask = grid.pilot_mask.numpy()[:, used]  # [num_ofdm_symbols, num_effective_subcarriers]
        # unit pilots: we hand sionna y / pilot on the pilot positions (our own sequence)
        pattern = PilotPattern(
            torch.as_tensor(mask[None, None]),
            torch.ones(1, 1, int(mask.sum()), dtype=torch.complex64),
        )
        rg = SionnaGrid(
            num_ofdm_symbols=grid.num_ofdm_symbols,
            fft_size=grid.fft_size,
            subcarrier_spacing=grid.subcarrier_spacing_hz,
            cyclic_prefix_length=grid.cp_length,
            num_guard_carriers=grid.num_guard_carriers,
            dc_null=grid.dc_null,
            pilot_pattern=pattern,
            device="cpu",
        )
        t_sym = grid.symbol_length / grid.sample_rate_hz
        cov_t = tdl_time_cov_mat(
            "A",
            self.speed_m_s,
            self.carrier_frequency_hz,
            t_sym,
            grid.num_ofdm_symbols,
            device="cpu",
        )
        cov_f = tdl_freq_cov_mat(
            "A", grid.subcarrier_spacing_hz, grid.fft_size, self.delay_spread_s, device="cpu"
        )[np.ix_(used, used)]  # [num_effective_subcarriers, num_effective_subcarriers]
        self._estimator = LMMSEChannelEstimator(rg, cov_t, cov_f, order="f-t", device="cpu")
        self._used = torch.as_tensor(used)

    def __repr__(self) -> str:
        return (
            f"LMMSEEstimator(speed_m_s={self.speed_m_s:g}, carrier_frequency_hz="
            f"{self.carrier_frequency_hz:g}, delay_spread_s={self.delay_spread_s:g})"
        )

    def __call__(self, y: Tensor, noise_var) -> tuple[Tensor, Tensor]:
        """Args: y [batch, num_slots * num_ofdm_symbols, fft_size] complex64; noise_var
        float or [batch].

        Returns: (h_hat, error_var) of y's shape (complex64, float32; 0 on unused carriers).
        """
        g = self.grid
        b, t, f = y.shape
        if f != g.fft_size or t % g.num_ofdm_symbols:
            raise ValueError(
                f"y must be [batch, k * {g.num_ofdm_symbols}, {g.fft_size}], got {tuple(y.shape)}"
            )
        slots = t // g.num_ofdm_symbols
        yy = y.reshape(b * slots, g.num_ofdm_symbols, f).clone()  # [batch * slots, symbols, F]
        mask = g.pilot_mask.to(y.device)
        yy[:, mask] = yy[:, mask] / g.pilots.to(y.device, y.dtype)  # LS on the pilots
        nv = torch.as_tensor(noise_var, dtype=torch.float32).reshape(-1).cpu()
        if nv.numel() not in (1, b):
            raise ValueError(f"noise_var must be a float or [batch={b}] tensor")
        nv = nv.expand(b).repeat_interleave(slots)  # [batch * slots]
        with torch.no_grad():
            h, err = self._estimator(yy[:, None, None], nv[:, None, None])
        h = h.reshape(b * slots, g.num_ofdm_symbols, -1)  # [batch * slots, symbols, used]
        err = err.reshape(b * slots, g.num_ofdm_symbols, -1)
        h_full = torch.zeros(b * slots, g.num_ofdm_symbols, f, dtype=torch.complex64)
        e_full = torch.zeros(b * slots, g.num_ofdm_symbols, f, dtype=torch.float32)
        h_full[..., self._used] = h.to(torch.complex64)
        e_full[..., self._used] = err.to(torch.float32).clamp_min(0.0)
        return h_full.reshape(b, t, f), e_full.reshape(b, t, f)
