"""Codeword error rate of one MCS by Monte Carlo: many equal codewords through a link at once.

This is what a calibration of the digital baseline needs (block error probability of a
codeword of ``coded_bits`` bits against SNR), measured with the very blocks of
:mod:`phy.digital.chain` (CRC24B, 5G LDPC with rate matching, QAM, app demapper, BP with
CRC early stop). Each codeword is one row of the batch that crosses the link, so a block
fading link gives every codeword its own fade and AWGN or fast fading are independent
per symbol.
"""

from __future__ import annotations

import torch
from torch import Tensor

from phy.digital.chain import (
    DEFAULT_NUM_ITER,
    _decode_group,
    _modem,
    codeword_code,
    rate_match,
)
from phy.digital.layout import CRC_BITS
from phy.digital.mcs import MCS, get_mcs


def codeword_errors(
    mcs: str | MCS,
    coded_bits: int,
    link,
    snr_db: float,
    num_codewords: int,
    generator: torch.Generator | None = None,
    num_iter: int = DEFAULT_NUM_ITER,
) -> Tensor:
    """Send ``num_codewords`` random codewords of ``coded_bits`` bits each and decode them.

    Args:
        mcs: name in :data:`phy.digital.MCS_TABLE` or an :class:`MCS`.
        coded_bits: E, coded bits per codeword; a multiple of the MCS's bits per symbol,
            with ``floor(E * code_rate) > 24`` (room for the CRC).
        link: ``link(x [num_codewords, E / bits_per_symbol] complex64, snr_db, generator)
            -> LinkOutput`` with unbiased ``x_hat`` (``equalizer="zf"``) and ``noise_var``.
        snr_db: Es/N0 per complex symbol in dB.
        num_codewords: trials (rows of the batch).
        generator: torch.Generator for the payload bits and the link.
    Returns:
        [num_codewords] bool, True where the codeword's CRC failed after decoding.
    """
    m = get_mcs(mcs)
    bps = m.bits_per_symbol
    if isinstance(coded_bits, bool) or not isinstance(coded_bits, int) or coded_bits % bps:
        raise ValueError(f"coded_bits must be a positive multiple of {bps}, got {coded_bits!r}")
    k = int(coded_bits * m.code_rate)
    if k <= CRC_BITS:
        raise ValueError(f"coded_bits={coded_bits} at {m.name} leaves no room for the CRC")
    if not isinstance(num_codewords, int) or num_codewords < 1:
        raise ValueError(f"num_codewords must be an integer >= 1, got {num_codewords!r}")
    crc_enc, _, enc, _ = codeword_code(k, coded_bits, bps, "cpu")
    mapper, demapper, _, _ = _modem(bps, "cpu")
    u = torch.randint(0, 2, (num_codewords, k - CRC_BITS), generator=generator).float()
    with torch.no_grad():
        c = rate_match(enc(crc_enc(u)), coded_bits)  # [num_codewords, E]
        x = mapper(c).to(torch.complex64)  # [num_codewords, E / bps]
        out = link(x, snr_db, generator=generator)
        llr = demapper(out.x_hat, out.noise_var)  # [num_codewords, E]
        _, ok, _ = _decode_group(llr, k, coded_bits, bps, num_iter)
    return ~ok
