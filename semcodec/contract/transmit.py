"""What every ``transmit_*`` scheme shares: its :class:`TransmitResult` (received images
[batch, 3, height, width] float32 in [0, 1] + stats), the run of a ``phy`` link
(:func:`run_link`) and the mid-grey a lost image is received as (:data:`LOST_IMAGE_VALUE`:
the receiver has nothing better to show).

The schemes: :func:`semcodec.jscc.link.transmit_jscc` (any semantic codec, with
transmitter-side refinement :func:`semcodec.jscc.link.refine_symbols`),
:func:`semcodec.digital.link.transmit_digital` and
:func:`semcodec.digital.link.transmit_ideal` (image codec + CRC + LDPC + QAM, or at
capacity), :func:`semcodec.links.uncoded.transmit_analog` (uncoded pixels).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
from torch import Tensor

from phy import Channel, FlatLink

LOST_IMAGE_VALUE = 0.5


@dataclass
class TransmitResult:
    """Received images [batch, 3, height, width] float32 and stats (sums over the batch, and lists
    per image)."""

    images: Tensor
    stats: dict = field(default_factory=dict)

    def __iter__(self):  # (images, stats) = result
        return iter((self.images, self.stats))


def run_link(link, x: Tensor, snr_db, generator):
    """(unbiased x_hat, noise_var [batch, num_symbols]) from a phy link or a bare phy channel
    (which gets a one-tap ZF receiver with perfect CSI)."""
    if isinstance(link, Channel):
        link = FlatLink(link, csi="perfect", equalizer="zf")
    out = link(x, snr_db, generator=generator)
    return out.x_hat, out.noise_var


def grey(shape) -> Tensor:
    return torch.full(shape, LOST_IMAGE_VALUE)


def check_num_symbols(num_symbols) -> int:
    if int(num_symbols) != num_symbols or int(num_symbols) < 1:
        raise ValueError(f"num_symbols must be a positive integer, got {num_symbols!r}")
    return int(num_symbols)
