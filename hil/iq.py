"""Sample formats at the host side of a front end: int8 interleaved I/Q (HackRF's wire
format, full scale 128) and the full-scale check every transmitter applies."""

from __future__ import annotations

import numpy as np


def from_int8_iq(raw: np.ndarray) -> np.ndarray:
    """[2 * num_samples] int8 interleaved I, Q -> [num_samples] complex64, full scale 1.0."""
    return (raw.astype(np.float32) / 128.0).view(np.complex64)


def to_int8_iq(samples: np.ndarray) -> np.ndarray:
    """[num_samples] complex in full scale [-1, 1] -> [2 * num_samples] int8 (round, clip at
    127)."""
    return quantize_ci8(np.asarray(samples, dtype=np.complex64).reshape(-1))


def full_scale_samples(samples) -> np.ndarray:
    """Check samples to transmit: [num_samples] or [1, num_samples], finite, |I|, |Q| <= 1.

    Returns:
        [num_samples], as given (complex or real).
    Raises:
        ValueError: naming what is wrong.
    """
    x = np.asarray(samples)
    if x.ndim == 2 and x.shape[0] == 1:
        x = x[0]
    if x.ndim != 1 or x.size == 0:
        raise ValueError(
            f"samples must be [num_samples] or [1, num_samples] complex, got shape {x.shape}"
        )
    if not np.all(np.isfinite(x)):
        raise ValueError("samples must be finite")
    peak = (
        max(np.abs(x.real).max(), np.abs(x.imag).max()) if np.iscomplexobj(x) else np.abs(x).max()
    )
    if peak > 1.0 + 1e-6:
        raise ValueError(f"samples must lie within full scale |I|, |Q| <= 1, peak is {peak:.3f}")
    return x


def quantize_ci8(y: np.ndarray) -> np.ndarray:
    """[num_samples] complex, full scale 1.0 -> [2 * num_samples] int8 (round, clip to [-128,
    127])."""
    inter = np.empty(2 * len(y), np.float32)
    inter[0::2] = y.real
    inter[1::2] = y.imag
    return np.clip(np.rint(inter * 128.0), -128, 127).astype(np.int8)
