"""A semantic codec through a ``phy`` link (:func:`transmit_jscc`), and the transmitter-side
refinement of its symbols for the image it holds (:func:`refine_symbols`)."""

from __future__ import annotations

import torch
from torch import Tensor

from phy import power_normalize
from semcodec.contract.box_focus import decode_received, encode_with_focus
from semcodec.contract.protocol import (
    Encoded,
    check_images,
    codec_limits,
    snr_per_image,
    symbol_budget,
)
from semcodec.contract.transmit import TransmitResult, run_link
from semcodec.jscc.codec import Codec

REFINE_STEPS = 50
"""Adam steps of :func:`refine_symbols` by default (each step runs the decoder forward and
backward once per image)."""
REFINE_LR = 0.03
"""Adam step of :func:`refine_symbols`, relative to the symbols' RMS per real dimension."""


def refine_symbols(
    codec: Codec,
    images: Tensor,
    encoded: Encoded,
    link,
    snr_db,
    steps: int = REFINE_STEPS,
    lr: float = REFINE_LR,
    generator: torch.Generator | None = None,
    decoder_snr_db=None,
    pixel_weights: Tensor | None = None,
) -> Encoded:
    """Transmitter-side refinement of the JSCC's symbols for this very image.

    The encoder is amortised: one network for every image. The transmitter can do better for
    the image it holds, because it knows the decoder (the shared knowledge base), the
    channel's kind (its fading distribution) and the average SNR; it does not know the draw
    the image will meet. Starting from ``encoded``, ``steps`` Adam steps on the symbols
    (before power normalisation) lower the MSE of the decoded image over draws of ``link``
    from the transmitter's own ``generator``: a stochastic descent on the expected
    distortion, with the same power per image as the encoder's symbols. The codec must
    declare a differentiable decode (``decode_differentiable``, the contract's optional
    capability); a focus box or tiles are unwrapped, so it sees its own meta. The receiver
    and the side information are unchanged (``meta`` is kept); the cost is ``steps`` decoder passes,
    forward and backward, at the transmitter. This is the amortisation gap closed at
    inference (stochastic latent refinement in learned compression).

    Args:
        encoded: ``codec.encode(images, ...)`` (whole images or focus mode).
        link: what the transmitter simulates: a ``phy`` link or bare channel, as for
            :func:`transmit_jscc`. Its draws come from ``generator``, never the real link's.
        snr_db: the average SNR the simulated link runs at.
        steps: Adam steps, >= 0 (0 returns ``encoded``).
        decoder_snr_db: the SNR the receiver's decoder is told (default ``snr_db``).
        pixel_weights: optional [batch, 1, height, width] weights of the squared error (the
            demanded objects above the rest); default uniform.
    Returns:
        :class:`Encoded` with the refined unit-power symbols and the same ``meta``.
    """
    if steps < 0:
        raise ValueError(f"steps must be >= 0, got {steps}")
    if steps and not codec_limits(codec).differentiable_decode:
        raise ValueError(f"codec {codec.name} cannot refine symbols (no decode_differentiable)")
    if not lr > 0:
        raise ValueError(f"lr must be > 0, got {lr}")
    if steps == 0:
        return encoded
    x = check_images(images)
    b = x.shape[0]
    snr = snr_per_image(snr_db, b)
    dec_snr = snr if decoder_snr_db is None else snr_per_image(decoder_snr_db, b)
    meta = encoded.meta
    v = torch.view_as_real(encoded.symbols.to(torch.complex64)).clone()  # [b, n, 2]
    scale = float(v.pow(2).mean().sqrt())
    v.requires_grad_(True)
    opt = torch.optim.Adam([v], lr=lr * scale)
    with torch.enable_grad():
        for _ in range(steps):
            sym = power_normalize(torch.view_as_complex(v))
            x_hat, nv = run_link(link, sym, snr, generator)
            y = decode_received(codec, x_hat, meta, dec_snr, noise_var=nv, differentiable=True)
            err = (y - x) ** 2 if pixel_weights is None else (y - x) ** 2 * pixel_weights
            (v.grad,) = torch.autograd.grad(err.mean(), [v])  # the weights stay as they are
            opt.step()
    sym = power_normalize(torch.view_as_complex(v.detach()))
    return Encoded(sym.to(torch.complex64), meta)


def transmit_jscc(
    codec: Codec,
    images: Tensor,
    link,
    snr_db,
    cbr: float,
    mask=None,
    generator: torch.Generator | None = None,
    demand_weights=None,
    rx_codec: Codec | None = None,
    encoded: Encoded | None = None,
) -> TransmitResult:
    """Images through a semantic codec (any :class:`semcodec.SemanticCodec`) and the link.
    The decoder gets the link's unbiased estimates with their per-symbol noise variance and
    the average SNR (the contract's convention). With a ``mask`` and a codec without
    ``supports_focus``, the objects' box is sent at the same symbol budget
    (:func:`semcodec.encode_with_focus`).

    Args:
        link: ``phy.FlatLink``/``phy.OFDMLink`` with ``equalizer="zf"`` (or a bare ``phy``
            channel: perfect-CSI ZF).
        snr_db: float or [batch], the average Es/N0 (the encoder's and decoder's SNR input).
        rx_codec: the receiver's codec (default the transmitter's); hashes must match.
        encoded: ``codec.encode(images, snr_db, cbr, mask, demand_weights)`` when the caller
            has it already (several draws of one image), else computed here.
    """
    x = check_images(images)
    enc = encoded or encode_with_focus(codec, x, snr_db, cbr, mask, demand_weights)
    with torch.no_grad():
        x_hat, nv = run_link(link, enc.symbols, snr_db, generator)
    rx = rx_codec or codec
    y = decode_received(rx, x_hat, enc.meta, snr_db, expected_sha256=codec.sha256, noise_var=nv)
    n = x.shape[0]
    return TransmitResult(
        y,
        {
            "num_symbols": enc.meta.num_symbols * n,
            "symbol_budget": symbol_budget(cbr, x.shape[2], x.shape[3]) * n,
            "cbr": enc.meta.cbr,
            "side_info_bits": enc.meta.side_info_bits() * n,
            "failed_codewords": 0,
        },
    )
