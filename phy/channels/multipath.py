"""Time-domain multipath: a tapped delay line applied to sample streams."""

from __future__ import annotations

import math

import torch
from torch import Tensor


def apply_taps(samples: Tensor, taps: Tensor) -> Tensor:
    """Linear convolution with a tapped delay line, truncated to the input length.

    ``y[n] = sum_l taps[l] * samples[n - l]`` (samples before the start are zero).

    Args:
        samples: [batch, num_samples] or [num_samples] complex64.
        taps: [batch, num_taps] or [num_taps] complex64 (tap l delays by l samples).
    Returns:
        samples' shape, complex64.
    """
    if not samples.is_complex() or not taps.is_complex():
        raise ValueError("samples and taps must be complex64 tensors")
    one = samples.dim() == 1
    s = samples.reshape(1, -1) if one else samples
    t = taps.reshape(1, -1) if taps.dim() == 1 else taps
    n, L = s.shape[-1], t.shape[-1]
    size = 1 << math.ceil(math.log2(n + L - 1))
    y = torch.fft.ifft(torch.fft.fft(s, size) * torch.fft.fft(t, size))[..., :n]
    return y.reshape(samples.shape).to(samples.dtype)


def taps_frequency_response(taps: Tensor, fft_size: int) -> Tensor:
    """Per-subcarrier gain of a tapped delay line, centred carrier order.

    ``H[k] = sum_l taps[l] exp(-2j pi (k - fft_size//2) l / fft_size)``.

    Args:
        taps: [..., num_taps] complex64.
    Returns:
        [..., fft_size] complex64.
    """
    return torch.fft.fftshift(torch.fft.fft(taps, fft_size, dim=-1), dim=-1)
