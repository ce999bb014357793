"""Carrier-frequency offset correction for real radios.

Pure numpy on IQ streams ``[num_samples] complex64``. CFO is expressed in subcarrier
spacings (``cfo_hz = cfo * sample_rate_hz / fft_size``). Detection and the CFO estimate
are :mod:`phy.detection`'s.
"""

from __future__ import annotations

import numpy as np


def correct_cfo(
    iq: np.ndarray, cfo_subcarriers: float, fft_size: int, start: int = 0
) -> np.ndarray:
    """Multiply by ``exp(-2j pi cfo (n - start) / fft_size)``: removes a CFO of ``cfo`` carriers.

    The rotation is the outer product of a coarse and a fine phasor table (one complex
    multiply per sample, exact to float64 rounding).
    """
    iq = np.asarray(iq, dtype=np.complex64)
    w = -2 * np.pi * cfo_subcarriers / fft_size
    block = 256
    nb = -(-iq.size // block)
    coarse = np.exp(1j * w * (np.arange(nb) * block - start)).astype(np.complex64)
    fine = np.exp(1j * w * np.arange(block)).astype(np.complex64)
    rot = np.multiply.outer(coarse, fine).reshape(-1)[: iq.size]
    return iq * rot
