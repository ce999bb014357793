"""The over-the-air frame header: a 12-bit frame number and a 4-bit check, BPSK.

Each frame of a burst starts with it, so frames can be lost or found out of order without
mixing up images; the receiver (:mod:`hil.ota.receiver`) checks it and drops a frame whose
header does not match where the frame was found.
"""

from __future__ import annotations

import numpy as np

HEADER_BITS = 16
MAX_FRAMES = 4096  # 12-bit frame numbers (+ a 4-bit check)
HEADER_REJECT_SIGMA = 3.0  # a header bit this many noise std against the expected bit: no match


def _check_nibble(number: int) -> int:
    return (number ^ (number >> 4) ^ (number >> 8) ^ 0x5) & 0xF


def _word(number: int) -> int:
    """The 16-bit header word: the frame number, its check nibble in the top 4 bits."""
    return number | (_check_nibble(number) << 12)


def header_symbols(frame_number: int, repeat: int) -> np.ndarray:
    """The frame header: 12-bit frame number + 4-bit check, BPSK (+1 for a 0 bit), LSB first.

    The 16-bit word is sent ``repeat`` times in a row (not bit by bit), so the copies land on
    different subcarriers and OFDM symbols and fade independently.

    Returns:
        [16 * repeat] complex64.
    """
    if not 0 <= int(frame_number) < MAX_FRAMES:
        raise ValueError(f"frame_number must be in [0, {MAX_FRAMES - 1}], got {frame_number!r}")
    bits = (_word(int(frame_number)) >> np.arange(HEADER_BITS)) & 1
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


def header_mismatch(x_hat: np.ndarray, repeat: int, number: int, noise_var) -> str | None:
    """Why the header that starts ``x_hat`` is not frame ``number``'s, or None when it agrees.

    The receiver numbers frames by where they start in the burst (a header alone does not
    decode reliably at low SNR); this is the check that the header does not contradict that
    number. Each of the 16 bits is soft-combined over its ``repeat`` copies with weights
    ``w = 1 / noise_var`` (unbiased symbols, BPSK on the real axis): with the bit as sent the
    sum ``s`` has mean ``W = sum(w)`` and standard deviation ``sqrt(W / 2)`` in the expected
    bit's direction. A bit whose sum lies more than ``HEADER_REJECT_SIGMA`` standard
    deviations on the other side is one the header was sent with differently (another
    frame's header, or a corrupted one): noise alone flips it that far with probability
    ``Q(3 + sqrt(2 W))`` per bit (at most Q(3) = 1.3e-3, as W goes to 0), so a frame is not
    dropped for low SNR alone.

    Args:
        x_hat: [>= 16 * repeat] equalised symbols, the header first.
        noise_var: [>= 16 * repeat] (or scalar) effective noise variance of each symbol.
    """
    n = HEADER_BITS * repeat
    x = np.real(np.asarray(x_hat)[:n]).astype(np.float64)
    nv = np.asarray(noise_var, np.float64)
    nv = np.maximum(np.broadcast_to(nv if nv.ndim == 0 else nv[:n], x.shape), 1e-6)
    w = 1.0 / nv
    soft = (x * w).reshape(repeat, HEADER_BITS).sum(axis=0)
    spread = np.sqrt((w * w * nv / 2).reshape(repeat, HEADER_BITS).sum(axis=0))
    expected = 1.0 - 2.0 * ((_word(number) >> np.arange(HEADER_BITS)) & 1)  # +1 for a 0 bit
    bad = np.flatnonzero(soft * expected < -HEADER_REJECT_SIGMA * spread)
    if bad.size == 0:
        return None
    decoded = decode_header(x_hat, repeat, noise_var)
    says = "its check nibble fails" if decoded is None else f"it decodes as frame {decoded}"
    return (
        f"header does not match frame {number} (found where frame {number} starts): "
        f"bit(s) {', '.join(str(int(b)) for b in bad)} contradict it; {says}"
    )
