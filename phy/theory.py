"""Closed-form uncoded error rates over AWGN and flat Rayleigh fading.

``snr_db`` is Es/N0 per symbol. Rayleigh means flat fast fading, h ~ CN(0, 1), perfect
CSI and coherent detection; its rates are the AWGN rates averaged over the exponential
distribution of the instantaneous SNR, in closed form.

BER of Gray-coded square QAM is the exact expression of K. Cho and D. Yoon, "On the
general BER expression of one- and two-dimensional amplitude modulations", IEEE Trans.
Commun. 50(7), 2002 (eq. 14), which is exact for binary-reflected Gray labelling per
dimension, the labelling of 3GPP 38.211 and sionna. Every term is ``c * erfc(a sqrt(g))``:
over Rayleigh, ``E[erfc(a sqrt(g))] = 1 - sqrt(a^2 gbar / (1 + a^2 gbar))``.
SER of square M-QAM: ``1 - (1 - p)^2`` with ``p = 2 (1 - 1/L) Q(sqrt(3 g / (M - 1)))``; over
Rayleigh with ``E[Q^2(sqrt(2 c g))] = 1/4 - (mu/pi) atan(1/mu)``, ``mu = sqrt(c gbar/(1 + c gbar))``
(M. K. Simon and M.-S. Alouini, Digital Communication over Fading Channels, ch. 8).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import erfc

from phy.modulation import bits_per_symbol

THEORY_CHANNELS = ("awgn", "rayleigh")


def _check(modulation: str, channel: str, snr_db) -> np.ndarray:
    bits_per_symbol(modulation)  # KeyError listing the known modulations
    if channel not in THEORY_CHANNELS:
        raise ValueError(f"channel must be one of {list(THEORY_CHANNELS)}, got {channel!r}")
    s = np.asarray(snr_db, dtype=np.float64)
    if not np.all(np.isfinite(s)):
        raise ValueError(f"snr_db must be finite, got {snr_db!r}")
    return s


def _erfc_avg(a: float, g: np.ndarray, channel: str) -> np.ndarray:
    """erfc(a sqrt(g)) over AWGN, or its average over Rayleigh fading with mean SNR g."""
    if channel == "awgn":
        return erfc(a * np.sqrt(g))
    c = a * a * g
    return 1.0 - np.sqrt(c / (1.0 + c))


def _qam_bit_terms(m: int) -> list[tuple[float, float]]:
    """(weight, a) pairs: BER = sum weight * erfc(a sqrt(Es/N0)) for Gray square M-QAM."""
    side = math.isqrt(m)
    bits_per_dim = int(math.log2(side))
    a0 = math.sqrt(3.0 / (2.0 * (m - 1)))
    terms: dict[int, float] = {}
    for k in range(1, bits_per_dim + 1):
        for i in range(int((1 - 2.0**-k) * side)):
            f = i * 2 ** (k - 1) / side
            w = (-1) ** math.floor(f) * (2 ** (k - 1) - math.floor(f + 0.5))
            terms[2 * i + 1] = terms.get(2 * i + 1, 0.0) + w / side / bits_per_dim
    return [(w, j * a0) for j, w in sorted(terms.items()) if w != 0.0]


def ber_theory(modulation: str, snr_db, channel: str = "awgn"):
    """Uncoded bit error rate at Es/N0 ``snr_db`` (float or array) -> float or ndarray."""
    s = _check(modulation, channel, snr_db)
    g = 10.0 ** (s / 10.0)
    out: np.ndarray | float
    if modulation == "bpsk":
        out = 0.5 * _erfc_avg(1.0, g, channel)
    else:
        out = sum(
            w * _erfc_avg(a, g, channel)
            for w, a in _qam_bit_terms(2 ** bits_per_symbol(modulation))
        )
    return float(out) if np.ndim(out) == 0 else out


def ser_theory(modulation: str, snr_db, channel: str = "awgn"):
    """Uncoded symbol error rate at Es/N0 ``snr_db`` (float or array) -> float or ndarray."""
    s = _check(modulation, channel, snr_db)
    g = 10.0 ** (s / 10.0)
    if modulation == "bpsk":
        out = 0.5 * _erfc_avg(1.0, g, channel)
        return float(out) if np.ndim(out) == 0 else out
    m = 2 ** bits_per_symbol(modulation)
    f = 1.0 - 1.0 / math.isqrt(m)
    c = 3.0 / (2.0 * (m - 1))  # Q(sqrt(3g/(M-1))) = Q(sqrt(2 c g)) = erfc(sqrt(c g)) / 2
    if channel == "awgn":
        q = 0.5 * erfc(np.sqrt(c * g))
        q2 = q * q
    else:
        mu = np.sqrt(c * g / (1.0 + c * g))
        q = 0.5 * (1.0 - mu)
        q2 = 0.25 - mu / math.pi * np.arctan(1.0 / mu)
    out = 4.0 * f * q - 4.0 * f * f * q2
    return float(out) if np.ndim(out) == 0 else out
