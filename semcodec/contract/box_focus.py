"""Focus for any codec: a codec without ``supports_focus`` sends the demanded objects'
bounding box, as an image of its own, at the view's symbol budget (:func:`focus_by_box`,
:func:`decode_box`); :func:`encode_with_focus` / :func:`decode_received` pick that or the
codec's own focus. Built only on :mod:`semcodec.contract.protocol` (and
:mod:`semcodec.contract.fitting`, which tiles and pads for a codec that declares an input size): the
codec sees only its own meta, never :class:`BoxMeta`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor
from torch.nn import functional as F

from semcodec.contract.fitting import fit_decode, fit_encode
from semcodec.contract.protocol import (
    FOCUS_FILL,
    MIN_SIDE_PX,
    CodecMeta,
    Encoded,
    box_bits,
    box_side_symbols,
    check_images,
    symbol_budget,
)

BOX_ALIGN_PX = 8  # the focus box's corners and sides are multiples of this (codecs downsample)


@dataclass(frozen=True)
class BoxMeta:
    """Side information of :func:`focus_by_box`: the codec's own meta for the box image.

    Attributes:
        inner: the codec's own meta (:class:`semcodec.contract.protocol.CodecMeta`) of the box image
            it encoded.
        height, width: the full image's size in pixels.
        crop: (top, left, height, width) in pixels of the box in the full image.
        num_symbols, cbr, codec_sha256: as :class:`semcodec.contract.protocol.CodecMeta`
            (``cbr`` over the full image).
    """

    inner: CodecMeta
    height: int
    width: int
    crop: tuple[int, int, int, int]
    num_symbols: int
    cbr: float
    codec_sha256: str

    def side_info_bits(self) -> int:
        """Bits of side information per image: the box (:func:`semcodec.contract.protocol.box_bits`)
        and the codec's own."""
        return box_bits(self.height, self.width) + self.inner.side_info_bits()


def mask_box(mask: Tensor, height: int, width: int) -> tuple[int, int, int, int]:
    """(top, left, rows, cols) in pixels: the bounding box of every mask value > 0.5 over the
    batch and the K objects, grown to multiples of :data:`BOX_ALIGN_PX` (at least 16 px),
    inside the image. An empty mask gives the whole image.

    Args:
        mask: [batch, K, height, width] or [batch, height, width], values in [0, 1].
    """
    m = mask.reshape(-1, height, width) > 0.5
    if not bool(m.any()):
        return (0, 0, height, width)
    rows = torch.nonzero(m.any(dim=0).any(dim=1)).flatten()
    cols = torch.nonzero(m.any(dim=0).any(dim=0)).flatten()

    def span(lo: int, hi: int, size: int) -> tuple[int, int]:
        a = BOX_ALIGN_PX
        start, end = lo // a * a, min(-(-(hi + 1) // a) * a, size)
        while end - start < min(2 * a, size):  # at least 16 px where the image allows
            start, end = max(start - a, 0), min(end + a, size)
        return start, end - start

    top, rows_px = span(int(rows[0]), int(rows[-1]), height)
    left, cols_px = span(int(cols[0]), int(cols[-1]), width)
    return (top, left, rows_px, cols_px)


def focus_by_box(codec, images: Tensor, mask: Tensor, budget_symbols: int, snr_db) -> Encoded:
    """Focus for any codec: send the objects' bounding box at the view's symbol budget.

    The box (:func:`mask_box`) is encoded as an image of its own at CBR
    ``(budget_symbols - box) / (3 * rows * cols)``, where ``box`` is what the box's side
    information costs (:func:`semcodec.contract.protocol.box_side_symbols`; a box edge on the
    image's border is coded as the border), capped at the codec's largest CBR. A budget below the
    codec's smallest CBR over the box sends the box downscaled (area) until it fits (at least
    8 px a side; a smaller budget is a ValueError); the receiver upsamples it back.
    :func:`decode_box` pastes it on a mid-grey canvas.

    Args:
        codec: any :class:`SemanticCodec`.
        images: [batch, 3, height, width] float32 in [0, 1].
        mask: [batch, K, height, width] or [batch, height, width] object masks in [0, 1].
        budget_symbols: complex symbols per image the view may use, >= 1.
        snr_db: float or [batch].
    Returns:
        :class:`Encoded` whose ``meta`` is a :class:`BoxMeta`.
    """
    x = check_images(images)
    _, _, h, w = x.shape
    if not isinstance(mask, Tensor) or mask.shape[-2:] != (h, w) or mask.shape[0] != x.shape[0]:
        raise ValueError(
            f"mask must be [batch, K, {h}, {w}] or [batch, {h}, {w}] (batch {x.shape[0]}), "
            f"got {tuple(getattr(mask, 'shape', ()))}"
        )
    if int(budget_symbols) < 1:
        raise ValueError(f"budget_symbols must be >= 1, got {budget_symbols!r}")
    top, left, rows, cols = mask_box(mask.float(), h, w)
    box = x[:, :, top : top + rows, left : left + cols]
    lo, hi = codec.cbr_range
    box_side = box_side_symbols(h, w)  # the box's side information rides in the budget
    budget = int(budget_symbols) - box_side
    if budget < 1:
        raise ValueError(
            f"budget_symbols {budget_symbols} does not carry the box's side information "
            f"({box_side} symbols)"
        )
    scale = min(1.0, math.sqrt(budget / (lo * 3 * rows * cols)))
    while True:  # downscale the box until the codec's message fits the budget
        size = (max(int(rows * scale), MIN_SIDE_PX), max(int(cols * scale), MIN_SIDE_PX))
        sent = box if size == (rows, cols) else F.interpolate(box, size=size, mode="area")
        cbr = min(max(budget / (3 * size[0] * size[1]), lo), hi)
        enc = fit_encode(codec, sent.clamp(0, 1), snr_db, cbr)
        if enc.meta.num_symbols > budget and cbr > lo:  # the codec rounded its rate up
            enc = fit_encode(codec, sent.clamp(0, 1), snr_db, lo)
        if enc.meta.num_symbols <= budget:
            break
        if size == (MIN_SIDE_PX, MIN_SIDE_PX):
            raise ValueError(
                f"budget_symbols {budget} is below the smallest message of codec "
                f"{codec.name} ({enc.meta.num_symbols} symbols for a {MIN_SIDE_PX} px box)"
            )
        scale *= 0.9
    meta = BoxMeta(
        inner=enc.meta,
        height=h,
        width=w,
        crop=(top, left, rows, cols),
        num_symbols=enc.meta.num_symbols,
        cbr=enc.meta.num_symbols / (3 * h * w),
        codec_sha256=enc.meta.codec_sha256,
    )
    return Encoded(enc.symbols, meta)


def decode_box(
    codec,
    x_hat: Tensor,
    meta: BoxMeta,
    snr_db,
    expected_sha256=None,
    noise_var=None,
    differentiable: bool = False,
) -> Tensor:
    """Receiver of :func:`focus_by_box`: [batch, 3, height, width] float32, the decoded box
    (upsampled bilinearly when it was sent downscaled) on a mid-grey (0.5) canvas. The codec
    decodes its own meta of the box image (``meta.inner``)."""
    y = fit_decode(codec, x_hat, meta.inner, snr_db, expected_sha256, noise_var, differentiable)
    top, left, rows, cols = meta.crop
    if tuple(y.shape[-2:]) != (rows, cols):
        y = F.interpolate(y, size=(rows, cols), mode="bilinear", align_corners=False)
    out = torch.full((y.shape[0], 3, meta.height, meta.width), FOCUS_FILL)
    out[:, :, top : top + rows, left : left + cols] = y.clamp(0, 1)
    return out


def encode_with_focus(
    codec, images: Tensor, snr_db, cbr: float, mask: Tensor | None = None, demand_weights=None
) -> Encoded:
    """``codec.encode`` for every codec: with a ``mask`` and a codec without
    ``supports_focus``, the objects' box at the same symbol budget (``cbr`` over the whole
    image, :func:`focus_by_box`); tiled and padded where the codec declares an input size
    (:func:`semcodec.fit_encode`)."""
    if mask is None or getattr(codec, "supports_focus", False):
        return fit_encode(codec, images, snr_db, cbr, mask=mask, demand_weights=demand_weights)
    x = check_images(images)
    try:
        budget = symbol_budget(cbr, x.shape[2], x.shape[3])
    except (TypeError, ValueError):
        raise ValueError(f"cbr must be a number, got {cbr!r}") from None
    return focus_by_box(codec, x, mask, budget, snr_db)


def decode_received(
    codec,
    x_hat: Tensor,
    meta,
    snr_db,
    expected_sha256=None,
    noise_var=None,
    differentiable: bool = False,
) -> Tensor:
    """``codec.decode`` for whatever :func:`encode_with_focus` sent (a :class:`BoxMeta` goes
    through :func:`decode_box`, tiles through :func:`semcodec.fit_decode`). With
    ``differentiable`` the codec's ``decode_differentiable`` (a declared capability,
    :class:`semcodec.contract.protocol.DifferentiableDecoder`) runs instead, with autograd on."""
    if isinstance(meta, BoxMeta):
        return decode_box(codec, x_hat, meta, snr_db, expected_sha256, noise_var, differentiable)
    return fit_decode(codec, x_hat, meta, snr_db, expected_sha256, noise_var, differentiable)
