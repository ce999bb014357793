"""The conventions every package shares: power, SNR, Eb/N0, CBR, PAPR.

* After power normalisation the mean ``|x|^2`` of each transmitted block (one image's
  symbols, one row of ``x``) is exactly ``power`` (1 by default).
* ``snr_db`` is Es/N0 per complex symbol: ``noise_var = 10**(-snr_db/10)`` per complex
  sample, ``noise_var/2`` per real dimension. This is sionna.phy's ``no``.
* ``cbr = k / n``: complex channel symbols per real source value (``height*width*3``).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

SNR_DB_RANGE = (-30.0, 60.0)
SPEED_OF_LIGHT_M_S = 299_792_458.0


def validate_snr_db(
    snr_db, name: str = "snr_db", low: float = SNR_DB_RANGE[0], high: float = SNR_DB_RANGE[1]
):
    """Raise ValueError naming ``name`` unless every value is finite and in [low, high]."""
    values = snr_db.detach().flatten().tolist() if isinstance(snr_db, Tensor) else [snr_db]
    for v in values:
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise ValueError(
                f"{name} must be a number in [{low:g}, {high:g}] dB, got {v!r}"
            ) from None
        if not math.isfinite(f) or not low <= f <= high:
            raise ValueError(f"{name} must be in [{low:g}, {high:g}] dB, got {v!r}")
    return snr_db


def snr_db_to_noise_var(snr_db):
    """Noise variance per complex sample for Es/N0 ``snr_db`` at unit signal power.

    Works on floats and tensors: ``10 ** (-snr_db / 10)``.
    """
    if isinstance(snr_db, Tensor):
        return torch.pow(10.0, -snr_db / 10.0)
    return 10.0 ** (-float(snr_db) / 10.0)


def noise_var_to_snr_db(noise_var):
    """Inverse of :func:`snr_db_to_noise_var`."""
    if isinstance(noise_var, Tensor):
        return -10.0 * torch.log10(noise_var)
    return -10.0 * math.log10(float(noise_var))


def ebno_db_to_snr_db(ebno_db: float, bits_per_symbol: int, coderate: float = 1.0) -> float:
    """Es/N0 in dB from Eb/N0 in dB: Es = Eb * bits_per_symbol * coderate."""
    return float(ebno_db) + 10.0 * math.log10(bits_per_symbol * coderate)


def snr_db_to_ebno_db(snr_db: float, bits_per_symbol: int, coderate: float = 1.0) -> float:
    """Eb/N0 in dB from Es/N0 in dB (inverse of :func:`ebno_db_to_snr_db`)."""
    return float(snr_db) - 10.0 * math.log10(bits_per_symbol * coderate)


def power_normalize(x: Tensor, power: float = 1.0, eps: float = 1e-12) -> Tensor:
    """Scale each block to mean ``|x|^2 = power``.

    Args:
        x: [batch, num_symbols] complex64 (any trailing shape: every dim but the
            first belongs to one block).
    Returns:
        Same shape and dtype; ``mean(|x|^2)`` over each block equals ``power``.
    """
    if x.dim() < 2:
        raise ValueError(f"x must be [batch, num_symbols], got shape {tuple(x.shape)}")
    dims = tuple(range(1, x.dim()))
    p = (
        (x.real**2 + x.imag**2).mean(dim=dims, keepdim=True)
        if x.is_complex()
        else (x**2).mean(dim=dims, keepdim=True)
    )
    return x * torch.sqrt(power / (p + eps))


def cbr(num_symbols: int, height: int, width: int, channels: int = 3) -> float:
    """Channel bandwidth ratio: complex symbols per real source value."""
    return num_symbols / float(height * width * channels)


def num_symbols_for_cbr(cbr_value: float, height: int, width: int, channels: int = 3) -> int:
    """Complex symbols that carry an image of this size at ``cbr_value`` (rounded)."""
    return int(round(cbr_value * height * width * channels))


def parse_cbr(value) -> float:
    """Parse ``1/16``, ``0.0625`` or a number; raise ValueError naming ``cbr``."""
    try:
        if isinstance(value, str) and "/" in value:
            num, den = value.split("/", 1)
            out = float(num) / float(den)
        else:
            out = float(value)
    except (ValueError, ZeroDivisionError):
        raise ValueError(
            f"cbr must be a fraction like 1/16 or a number in (0, 1], got {value!r}"
        ) from None
    if not math.isfinite(out) or not 0.0 < out <= 1.0:
        raise ValueError(f"cbr must be in (0, 1], got {value!r}")
    return out


def papr_db(x: Tensor) -> Tensor:
    """Peak-to-average power ratio of each block in dB.

    Args:
        x: [batch, num_samples] complex.
    Returns:
        [batch] float32: ``10 log10(max|x|^2 / mean|x|^2)``.
    """
    p = x.abs() ** 2
    p = p.reshape(p.shape[0], -1)
    return 10.0 * torch.log10(p.max(dim=1).values / p.mean(dim=1).clamp_min(1e-30))


def clip_papr(x: Tensor, max_papr_db: float) -> Tensor:
    """Clip amplitudes to ``sqrt(10**(max_papr_db/10) * mean|x|^2)`` per block, keeping phase.

    Args:
        x: [batch, num_samples] complex.
    Returns:
        Same shape; every block's PAPR <= ``max_papr_db`` (power is not renormalised).
    """
    if not math.isfinite(max_papr_db) or max_papr_db < 0:
        raise ValueError(f"max_papr_db must be >= 0 dB, got {max_papr_db!r}")
    dims = tuple(range(1, x.dim()))
    mean_p = (x.abs() ** 2).mean(dim=dims, keepdim=True)
    limit = torch.sqrt(10.0 ** (max_papr_db / 10.0) * mean_p)
    mag = x.abs()
    scale = torch.where(mag > limit, limit / mag.clamp_min(1e-30), torch.ones_like(mag))
    return x * scale
