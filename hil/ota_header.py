"""The over-the-air frame header: a 12-bit frame number and a 4-bit check, BPSK.

Each frame of a burst starts with it, so frames can be lost or found out of order without
mixing up images; the receiver (:mod:`hil.ota_receiver`) checks it and drops a frame whose
header does not match where the frame was found.
"""

from __future__ import annotations

import numpy as np

HEADER_BITS = 16
MAX_FRAMES = 4096  # 12-bit frame numbers (+ a 4-bit check)


def _check_nibble(number: int) -> int:
    return (number ^ (number >> 4) ^ (number >> 8) ^ 0x5) & 0xF


def header_symbols(frame_number: int, repeat: int) -> np.ndarray:
    """The frame header: 12-bit frame number + 4-bit check, BPSK (+1 for a 0 bit), LSB first.

    The 16-bit word is sent ``repeat`` times in a row (not bit by bit), so the copies land on
    different subcarriers and OFDM symbols and fade independently.

    Returns:
        [16 * repeat] complex64.
    """
    if not 0 <= int(frame_number) < MAX_FRAMES:
        raise ValueError(f"frame_number must be in [0, {MAX_FRAMES - 1}], got {frame_number!r}")
    word = int(frame_number) | (_check_nibble(int(frame_number)) << 12)
    bits = (word >> np.arange(HEADER_BITS)) & 1
    return np.tile(1.0 - 2.0 * bits, repeat).astype(np.complex64)


def decode_header(x_hat: np.ndarray, repeat: int, noise_var=None) -> int | None:
    """Inverse of :func:`header_symbols`: soft-combines the copies (weighted by 1/noise_var);
    None when the check nibble does not match (a corrupted header)."""
    n = HEADER_BITS * repeat
    x = np.real(np.asarray(x_hat)[:n]).astype(np.float64)
    w = 1.0 if noise_var is None else 1.0 / np.maximum(np.asarray(noise_var, np.float64)[:n], 1e-6)
    soft = (x * w).reshape(repeat, HEADER_BITS).sum(axis=0)
    word = int(np.sum((soft < 0).astype(np.int64) << np.arange(HEADER_BITS)))
    number = word & (MAX_FRAMES - 1)
    return number if (word >> 12) == _check_nibble(number) else None
