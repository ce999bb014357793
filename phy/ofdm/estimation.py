"""Least-squares channel estimation on pilots with linear interpolation in frequency and time."""

from __future__ import annotations

import numpy as np
import torch
from numpy.typing import ArrayLike
from torch import Tensor

from phy.ofdm.resource_grid import ResourceGrid

INTERPOLATIONS = ("linear", "nearest")


def interpolation_matrix(
    positions: ArrayLike, targets: ArrayLike, kind: str = "linear"
) -> np.ndarray:
    """[len(targets), len(positions)] weights that interpolate values known at ``positions``.

    Linear between neighbours, the nearest value beyond the ends (no extrapolation).
    """
    if kind not in INTERPOLATIONS:
        raise ValueError(f"interpolation must be one of {list(INTERPOLATIONS)}, got {kind!r}")
    p = np.asarray(positions, dtype=np.float64)
    tt = np.asarray(targets, dtype=np.float64)
    w = np.zeros((len(tt), len(p)))
    for i, t in enumerate(tt):
        if len(p) == 1 or t <= p[0]:
            w[i, 0] = 1.0
        elif t >= p[-1]:
            w[i, -1] = 1.0
        else:
            j = int(np.searchsorted(p, t, side="right")) - 1
            a = (t - p[j]) / (p[j + 1] - p[j])
            if kind == "nearest":
                w[i, j + (a > 0.5)] = 1.0
            else:
                w[i, j], w[i, j + 1] = 1.0 - a, a
    return w


def ls_channel_estimate(y: Tensor, grid: ResourceGrid, noise_var, interpolation: str = "linear"):
    """LS estimates ``y_p / p`` on the pilots, interpolated over the whole grid.

    Frequency first (across the used carriers of each pilot symbol), then time (across
    pilot symbols, held constant before the first and after the last). Both steps are
    linear, so the estimation-error variance is ``noise_var * sum(w_t^2) * sum(w_f^2)``.

    Args:
        y: [batch, num_slots * num_ofdm_symbols, fft_size] complex64 received grid.
        noise_var: float or [batch] noise variance per resource element.
        interpolation: ``"linear"`` or ``"nearest"``.
    Returns:
        (h_hat [batch, num_slots * num_ofdm_symbols, fft_size] complex64 (0 on unused carriers),
         error_var [batch, num_slots * num_ofdm_symbols, fft_size] float32).
    """
    if not grid.pilot_ofdm_symbols:
        raise ValueError("grid has no pilot_ofdm_symbols: pilot-based estimation needs pilots")
    b, t, f = y.shape
    if f != grid.fft_size or t % grid.num_ofdm_symbols:
        raise ValueError(
            f"y must be [batch, k * {grid.num_ofdm_symbols}, {grid.fft_size}], got {tuple(y.shape)}"
        )
    slots = t // grid.num_ofdm_symbols
    ps, pk = list(grid.pilot_ofdm_symbols), grid.pilot_subcarriers
    yy = y.reshape(b, slots, grid.num_ofdm_symbols, f)
    pilots = grid.pilots.to(y.device, y.dtype).reshape(len(ps), len(pk))
    h_p = yy[:, :, ps][..., pk] / pilots  # [batch, slots, num_pilot_symbols, num_pilot_carriers]
    wf = np.zeros((f, len(pk)))
    wf[grid.used_subcarriers] = interpolation_matrix(pk, grid.used_subcarriers, interpolation)
    wt = interpolation_matrix(ps, np.arange(grid.num_ofdm_symbols), interpolation)
    wf_t = torch.tensor(wf, dtype=y.dtype, device=y.device)
    wt_t = torch.tensor(wt, dtype=y.dtype, device=y.device)
    h_hat = wt_t @ h_p @ wf_t.T  # [batch, slots, num_ofdm_symbols, fft_size]
    gain = torch.tensor(
        np.outer((wt**2).sum(1), (wf**2).sum(1)), dtype=torch.float32, device=y.device
    )
    nv = torch.as_tensor(noise_var, dtype=torch.float32, device=y.device).reshape(-1, 1, 1)
    err = (nv * gain.repeat(slots, 1)).expand(b, t, f)
    return h_hat.reshape(b, t, f), err.contiguous()
