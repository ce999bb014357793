"""The one channel interface: complex symbols in; received symbols and channel state out.

Every channel is a ``torch.nn.Module`` whose ``forward(x, snr_db, generator=None)``
returns a :class:`ChannelOutput`. Channels are differentiable with respect to ``x`` so a
codec can train through them, and draw all randomness from the explicit ``generator``.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor


@dataclass
class ChannelOutput:
    """What a receiver gets.

    Attributes:
        y: received symbols, same shape as the input ``x`` ([batch, num_symbols] complex64,
            or [batch, num_ofdm_symbols, fft_size] for frequency-domain channels).
        h: channel coefficients a receiver with perfect CSI may use, broadcastable to ``y``
            (complex64; ``None`` for AWGN, meaning h = 1).
        noise_var: noise variance per complex sample, [batch] float32.
        outage: [batch] bool, True where no propagation path exists (ray-traced channels);
            ``None`` when the channel cannot be in outage.
    """

    y: Tensor
    h: Tensor | None
    noise_var: Tensor
    outage: Tensor | None = None

    def equalized(self, mode: str = "mmse") -> Tensor:
        """One-tap equalisation with the perfect CSI ``h``: ``"zf"`` or ``"mmse"``."""
        if self.h is None:
            return self.y
        nv = self.noise_var.reshape(-1, *([1] * (self.y.dim() - 1)))
        if mode == "zf":
            return self.y / torch.where(self.h.abs() > 0, self.h, torch.ones_like(self.h))
        if mode == "mmse":
            return self.y * self.h.conj() / (self.h.abs() ** 2 + nv)
        raise ValueError(f"mode must be 'zf' or 'mmse', got {mode!r}")


class Channel(torch.nn.Module):
    """Base class: subclasses implement ``forward(x, snr_db, generator=None) -> ChannelOutput``.

    Args of forward:
        x: [batch, num_symbols] complex64 (unit mean power per block by convention).
        snr_db: float, or [batch] float tensor: Es/N0 per complex symbol in dB.
        generator: torch.Generator for noise and fading draws.
    """

    @property
    def kind(self) -> str:
        """Its ``phy.CHANNELS`` name: the fading distribution a transmitter may know (never the
        draw). Set by each subclass (a class attribute, or a property where it depends on the
        mode); ``""`` here."""
        return ""

    def record(self) -> dict:
        """What a result records of this channel (JSON-serialisable): ``{"channel": kind}``
        here; channels with parameters a result depends on add them (the TR 38.901 ones
        their profile and pinned ``spec_version``)."""
        return {"channel": self.kind}

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> ChannelOutput:  # noqa: D102
        raise NotImplementedError
