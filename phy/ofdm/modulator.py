"""OFDM modulation and demodulation with orthonormal FFTs and a cyclic prefix."""

from __future__ import annotations

import torch
from torch import Tensor


def ofdm_modulate(grid_symbols: Tensor, cp_length: int) -> Tensor:
    """Frequency-domain grid -> time-domain samples.

    Orthonormal IFFT (``norm="ortho"``: energy is preserved) of each OFDM symbol, whose
    carriers are in centred order, then the last ``cp_length`` samples are prepended.

    Args:
        grid_symbols: [batch, num_ofdm_symbols, fft_size] complex64.
        cp_length: cyclic prefix length in samples, >= 0.
    Returns:
        [batch, num_ofdm_symbols * (fft_size + cp_length)] complex64.
    """
    if grid_symbols.dim() != 3 or not grid_symbols.is_complex():
        raise ValueError(
            "grid_symbols must be [batch, num_ofdm_symbols, fft_size] complex64, got "
            f"{tuple(grid_symbols.shape)}"
        )
    fft_size = grid_symbols.shape[-1]
    if not 0 <= cp_length <= fft_size:
        raise ValueError(f"cp_length must be in [0, {fft_size}], got {cp_length!r}")
    t = torch.fft.ifft(torch.fft.ifftshift(grid_symbols, dim=-1), dim=-1, norm="ortho")
    t = torch.cat(
        [t[..., fft_size - cp_length :], t], dim=-1
    )  # [batch, num_ofdm_symbols, fft_size + cp]
    return t.reshape(t.shape[0], -1)


def ofdm_demodulate(
    samples: Tensor, fft_size: int, cp_length: int, cp_offset: int | None = None
) -> Tensor:
    """Time-domain samples -> frequency-domain grid (inverse of :func:`ofdm_modulate`).

    Args:
        samples: [batch, num_ofdm_symbols * (fft_size + cp_length)] complex64.
        cp_offset: where in each symbol the FFT window starts, in [0, cp_length]; default
            ``cp_length`` (right after the prefix). Starting earlier, inside the prefix,
            tolerates a late timing estimate and adds a linear phase ramp of
            ``exp(-2j pi k (cp_length - cp_offset) / fft_size)`` that an equaliser absorbs;
            this function removes that ramp so the identity holds for any offset.
    Returns:
        [batch, num_ofdm_symbols, fft_size] complex64 in centred carrier order.
    """
    if samples.dim() != 2 or not samples.is_complex():
        raise ValueError(
            f"samples must be [batch, num_samples] complex64, got {tuple(samples.shape)}"
        )
    sym_len = fft_size + cp_length
    if samples.shape[1] % sym_len:
        raise ValueError(
            f"samples: num_samples ({samples.shape[1]}) must be a multiple of fft_size + cp_length "
            f"({sym_len})"
        )
    off = cp_length if cp_offset is None else int(cp_offset)
    if not 0 <= off <= cp_length:
        raise ValueError(f"cp_offset must be in [0, {cp_length}], got {cp_offset!r}")
    s = samples.reshape(samples.shape[0], -1, sym_len)[
        ..., off : off + fft_size
    ]  # [batch, num_ofdm_symbols, fft_size]
    f = torch.fft.fftshift(torch.fft.fft(s, dim=-1, norm="ortho"), dim=-1)
    if off != cp_length:
        k = torch.arange(fft_size, device=s.device) - fft_size // 2
        f = f * torch.exp(2j * torch.pi * k * (cp_length - off) / fft_size).to(f.dtype)
    return f
