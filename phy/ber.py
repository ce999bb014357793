"""Monte-Carlo uncoded bit and symbol error counts over a link."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from phy.modulation import bits_per_symbol, hard_decision, indices_to_bits, map_bits


@dataclass(frozen=True)
class ErrorCounts:
    """Errors counted over one SNR point."""

    num_bits: int
    num_errors: int
    num_symbols: int
    symbol_errors: int

    @property
    def ber(self) -> float:
        return self.num_errors / self.num_bits

    @property
    def ser(self) -> float:
        return self.symbol_errors / self.num_symbols


def simulate_uncoded(
    modulation: str,
    link: Callable,
    snr_db: float,
    num_bits: int,
    generator: torch.Generator | None = None,
    chunk_symbols: int = 1 << 17,
    progress: Callable[[int], None] | None = None,
) -> ErrorCounts:
    """Send ``num_bits`` random bits (rounded up to whole symbols) through ``link``.

    Hard decisions by minimum distance on the equalised symbols (ML for a one-tap channel
    with perfect CSI and ZF). ``progress(num_bits_done_in_chunk)`` is called per chunk.

    Args:
        modulation: "bpsk", "qpsk", "16qam" or "64qam".
        link: ``link(x [1, n] complex64, snr_db, generator) -> LinkOutput``.
    """
    k = bits_per_symbol(modulation)
    if int(num_bits) < 1:
        raise ValueError(f"num_bits must be >= 1, got {num_bits!r}")
    total_symbols = -(-int(num_bits) // k)
    errors = sym_errors = 0
    done = 0
    with torch.no_grad():
        while done < total_symbols:
            n = min(chunk_symbols, total_symbols - done)
            bits = torch.randint(0, 2, (1, n * k), generator=generator, dtype=torch.uint8)
            x = map_bits(bits, modulation)  # [1, n]
            out = link(x, snr_db, generator=generator)
            idx = hard_decision(out.x_hat, modulation)
            errors += int((indices_to_bits(idx, modulation) != bits).sum())
            tx_idx = (bits.reshape(1, n, k).long() * (2 ** torch.arange(k - 1, -1, -1))).sum(-1)
            sym_errors += int((idx != tx_idx).sum())
            done += n
            if progress is not None:
                progress(n * k)
    return ErrorCounts(total_symbols * k, errors, total_symbols, sym_errors)
