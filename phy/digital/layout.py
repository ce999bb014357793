"""How a payload is cut into LDPC codewords and how many symbols it needs (pure arithmetic).

Layout of ``num_symbols`` channel symbols at one MCS (TS 38.212 5.2.2 / 5.4.2 in spirit):

* ``G = num_symbols * bits_per_symbol`` coded bits are split into
  ``C = ceil(G / max_codeword_bits(mcs))`` codewords whose lengths differ by at most one symbol
  (the first ``C - num_symbols % C`` codewords get ``floor(num_symbols / C)`` symbols, the
  rest one more), so a codeword never straddles a symbol.
* A codeword of ``E`` coded bits carries ``k = floor(E * code_rate)`` LDPC information
  bits, of which the last ``CRC_BITS`` (24, CRC24B as for 5G code blocks) are its own CRC:
  ``k - 24`` payload bits. Every codeword is checked on its own, so a receiver knows which
  codewords failed.
* Below the mother rate 1/5 a codeword is the rate-1/5 mother codeword of ``5 k`` bits
  (:func:`mother_bits`) repeated cyclically to ``E`` bits. No codeword sends more than
  ``MAX_CODED_BITS`` distinct bits, so the longest codeword at a rate ``R < 1/5`` is
  ``MAX_CODED_BITS / (5 R)`` bits (:func:`max_codeword_bits`).
* Payload bits fill the codewords in order; unused capacity is zero padding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from phy.digital.mcs import MCS, MOTHER_RATE, get_mcs

CRC_POLY = "CRC24B"
CRC_BITS = 24
MAX_CODED_BITS = 3840
"""Most distinct coded bits of one codeword (a multiple of 2, 4 and 6): the codeword's
length at rates >= 1/5, its mother codeword's below. Longer payloads use more codewords;
decoding cost per bit does not depend on this length."""


def max_codeword_bits(mcs: str | MCS) -> int:
    """Longest codeword ``E`` at ``mcs``: :data:`MAX_CODED_BITS` at rates >= 1/5, else the
    length whose mother codeword has at most that many bits (a multiple of bits per symbol)."""
    m = get_mcs(mcs)
    if m.code_rate >= MOTHER_RATE:
        return MAX_CODED_BITS
    e = math.floor(MAX_CODED_BITS * MOTHER_RATE / m.code_rate)
    return e - e % m.bits_per_symbol


def mother_bits(ldpc_k: int, coded_bits: int) -> int:
    """Distinct coded bits of a codeword of ``ldpc_k`` information bits sent in ``coded_bits``
    bits: all of them at rates >= 1/5, else the rate-1/5 mother codeword's ``5 k`` (sionna's
    ``LDPC5GEncoder`` stops there), which the rate matcher repeats up to ``coded_bits``."""
    return min(coded_bits, int(ldpc_k / MOTHER_RATE))


@dataclass(frozen=True)
class CodewordLayout:
    """Codeword sizes for ``num_symbols`` symbols at one MCS.

    Attributes:
        num_symbols: channel symbols in the block.
        mcs: the scheme.
        num_short: number of codewords with ``short_symbols`` symbols (they come first).
        num_long: number with ``short_symbols + 1`` symbols (they follow).
        short_symbols: symbols of a short codeword.
    """

    num_symbols: int
    mcs: MCS
    num_short: int
    num_long: int
    short_symbols: int

    @property
    def num_codewords(self) -> int:
        return self.num_short + self.num_long

    def coded_bits(self, index: int) -> int:
        """E: coded bits of codeword ``index``."""
        extra = 1 if index >= self.num_short else 0
        return (self.short_symbols + extra) * self.mcs.bits_per_symbol

    def ldpc_k(self, index: int) -> int:
        """k: LDPC information bits of codeword ``index`` (payload + CRC)."""
        return math.floor(self.coded_bits(index) * self.mcs.code_rate)

    def payload_bits(self, index: int) -> int:
        """Payload bits of codeword ``index`` (``ldpc_k - CRC_BITS``)."""
        return self.ldpc_k(index) - CRC_BITS

    @property
    def capacity_bits(self) -> int:
        """Payload bits the whole block carries (0 when a codeword cannot hold a CRC)."""
        if self.payload_bits(0) < 1:  # only possible with a single, tiny codeword
            return 0
        return sum(count * (k - CRC_BITS) for _, count, k, _ in self.groups())

    def groups(self) -> list[tuple[int, int, int, int]]:
        """Runs of equal codewords: ``(first_index, count, ldpc_k, coded_bits)``."""
        out = []
        if self.num_short:
            out.append((0, self.num_short, self.ldpc_k(0), self.coded_bits(0)))
        if self.num_long:
            i = self.num_short
            out.append((i, self.num_long, self.ldpc_k(i), self.coded_bits(i)))
        return out


def _check_num_symbols(num_symbols) -> int:
    if isinstance(num_symbols, bool) or not isinstance(num_symbols, int) or num_symbols < 1:
        raise ValueError(f"num_symbols must be an integer >= 1, got {num_symbols!r}")
    return num_symbols


def codeword_layout(num_symbols: int, mcs: str | MCS) -> CodewordLayout:
    """Codeword sizes for a block of ``num_symbols`` symbols (see the module docstring)."""
    num_symbols = _check_num_symbols(num_symbols)
    m = get_mcs(mcs)
    coded = num_symbols * m.bits_per_symbol
    c = -(-coded // max_codeword_bits(m))
    short_symbols, num_long = divmod(num_symbols, c)
    return CodewordLayout(num_symbols, m, c - num_long, num_long, short_symbols)


def payload_capacity_bits(num_symbols: int, mcs: str | MCS) -> int:
    """Payload bits that fit in ``num_symbols`` channel uses at ``mcs``, CRC overhead removed.

    ``encode_bytes(payload, mcs, num_symbols)`` accepts any payload of up to
    ``payload_capacity_bits(num_symbols, mcs) // 8`` bytes. Returns 0 when the block is too
    short for one codeword with its 24-bit CRC.
    """
    return codeword_layout(num_symbols, mcs).capacity_bits


def min_num_symbols(num_bytes: int, mcs: str | MCS) -> int:
    """Fewest symbols whose capacity holds ``num_bytes`` bytes at ``mcs``.

    This is how many symbols ``encode_bytes(payload, mcs)`` emits when ``num_symbols`` is
    not given.
    """
    if isinstance(num_bytes, bool) or not isinstance(num_bytes, int) or num_bytes < 1:
        raise ValueError(f"num_bytes must be an integer >= 1, got {num_bytes!r}")
    m = get_mcs(mcs)
    bits = 8 * num_bytes
    # Every codeword has at most max_codeword_bits(m) coded bits, so at least c_min codewords
    # (each with its CRC) are needed, and capacity(s) <= s * bits_per_symbol * code_rate
    # - 24 * c_min: start at that lower bound and step up (capacity is not monotone across
    # a change in the number of codewords, so no bisection).
    per_symbol = m.bits_per_symbol * m.code_rate
    c_min = -(-bits // (math.floor(max_codeword_bits(m) * m.code_rate) - CRC_BITS))
    s = max(1, math.ceil((bits + CRC_BITS * c_min) / per_symbol))
    while codeword_layout(s, m).capacity_bits < bits:
        s += 1
    return s
