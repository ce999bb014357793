"""Modulation and coding schemes (MCS) of the digital baseline: QAM order x LDPC code rate.

A 5G-like table: QPSK at the low-spectral-efficiency rates of TS 38.214 Table 5.1.3.1-3
(R x 1024 = 30, 40, 50, 64, 78, 99, 120, 157, 193, 251, 308), then QPSK at 1/3..3/4, 16-QAM
at 1/2..3/4, 64-QAM at 2/3..5/6 (Table 5.1.3.1-1 spans the same ground). Names read
``<modulation>-<rate>``, e.g. ``"16qam-3/4"`` or ``"qpsk-30/1024"``. Spectral efficiency
``bits_per_symbol * code_rate`` counts the CRC as payload overhead (see
:func:`phy.digital.payload_capacity_bits` for the exact count).

Rates below :data:`MOTHER_RATE` (1/5, LDPC base graph 2's mother rate) send the mother
codeword and then repeat its bits cyclically up to the codeword's length, as the 38.212 rate
matcher wraps around its circular buffer; the receiver adds the repeats' LLRs before decoding
(:mod:`phy.digital.chain`).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

from common import Registry
from phy.modulation import MODULATIONS

QAM_MODULATIONS = ("qpsk", "16qam", "64qam")
"""The modulations of :data:`phy.MODULATIONS` that the LDPC chain maps (sionna's QAM)."""
MOTHER_RATE = Fraction(1, 5)
"""Lowest rate of the 5G LDPC code itself (base graph 2); lower rates repeat its bits."""


@dataclass(frozen=True)
class MCS:
    """One modulation and coding scheme.

    Attributes:
        name: registry key, ``"<modulation>-<p>/<q>"``.
        modulation: ``"qpsk"``, ``"16qam"`` or ``"64qam"`` (Gray-mapped square QAM, unit
            average energy, sionna's ``Constellation("qam", bits_per_symbol)``).
        code_rate: LDPC code rate k/n as an exact fraction in (0, 1) (k includes the CRC).
    """

    name: str
    modulation: str
    code_rate: Fraction

    def __post_init__(self):
        if self.modulation not in QAM_MODULATIONS:
            raise ValueError(
                f"modulation must be one of {', '.join(QAM_MODULATIONS)}, got {self.modulation!r}"
            )
        if not isinstance(self.code_rate, Fraction) or not 0 < self.code_rate < 1:
            raise ValueError(f"code_rate must be a Fraction in (0, 1), got {self.code_rate!r}")

    @property
    def bits_per_symbol(self) -> int:
        """Coded bits per complex channel symbol (2, 4 or 6)."""
        return MODULATIONS[self.modulation]

    @property
    def spectral_efficiency(self) -> float:
        """Coded-rate bits per channel use, ``bits_per_symbol * code_rate`` (CRC included)."""
        return float(self.bits_per_symbol * self.code_rate)

    @property
    def repetition(self) -> float:
        """How many times each mother-code bit is sent on average (1 at rates >= 1/5)."""
        return float(max(MOTHER_RATE / self.code_rate, Fraction(1)))


def _mcs(modulation: str, rate: str) -> MCS:
    return MCS(f"{modulation}-{rate}", modulation, Fraction(rate))


MCS_TABLE = Registry[MCS](
    "MCS",
    {
        m.name: m
        for m in (
            *(_mcs("qpsk", f"{r}/1024") for r in (30, 40, 50, 64, 78, 99, 120, 157, 193, 251, 308)),
            _mcs("qpsk", "1/3"),
            _mcs("qpsk", "1/2"),
            _mcs("qpsk", "2/3"),
            _mcs("qpsk", "3/4"),
            _mcs("16qam", "1/2"),
            _mcs("16qam", "2/3"),
            _mcs("16qam", "3/4"),
            _mcs("64qam", "2/3"),
            _mcs("64qam", "3/4"),
            _mcs("64qam", "5/6"),
        )
    },
)
"""name -> :class:`MCS`, ordered by increasing spectral efficiency."""


def get_mcs(mcs: str | MCS) -> MCS:
    """Return the :class:`MCS` for a name (or pass one through).

    Raises:
        KeyError: unknown name; the message lists the known names.
    """
    return mcs if isinstance(mcs, MCS) else MCS_TABLE[mcs]
