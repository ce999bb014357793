"""Images of any size for a codec that declares an input size (:mod:`semcodec.contract.protocol`:
``input_size``, ``input_multiple``, ``symbol_multiple``): the commands tile and pad for it,
so the codec never has to (:func:`fit_encode`, :func:`fit_decode`). Built only on the
contract; a codec that declares nothing is called as it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor
from torch.nn import functional as F

from semcodec.contract.protocol import (
    CodecMeta,
    Encoded,
    check_images,
    codec_limits,
    snr_per_image,
    symbol_budget,
)


@dataclass(frozen=True)
class TiledMeta:
    """Side information of :func:`fit_encode` for a codec with a declared input size.

    Attributes:
        inner: the codec's own meta of each tile, row by row (what its ``decode`` reads).
        height, width: the image's size in pixels.
        tile: (height, width) in pixels of each tile as the codec took it.
        grid: (rows, cols) of tiles; the padded image is ``grid * tile``.
        num_symbols, cbr, codec_sha256: as :class:`semcodec.contract.protocol.CodecMeta` (``cbr``
            over the image as given).
    """

    inner: tuple[CodecMeta, ...]
    height: int
    width: int
    tile: tuple[int, int]
    grid: tuple[int, int]
    num_symbols: int
    cbr: float
    codec_sha256: str

    def side_info_bits(self) -> int:
        """The tiles' own side information (the tiling follows from the image's size)."""
        return sum(int(m.side_info_bits()) for m in self.inner)


def tiling(codec, height: int, width: int) -> tuple[tuple[int, int], tuple[int, int]] | None:
    """((tile height, tile width), (rows, cols)) the codec's declaration asks for an image of
    ``height x width`` px, or None when it takes the image as it is."""
    lim = codec_limits(codec)
    if lim.any_size:
        return None
    if lim.input_size is not None:
        th, tw = lim.input_size
        return (th, tw), (math.ceil(height / th), math.ceil(width / tw))
    m = lim.input_multiple
    return (math.ceil(height / m) * m, math.ceil(width / m) * m), (1, 1)


def _tiles(x: Tensor, tile: tuple[int, int], grid: tuple[int, int], mode: str) -> list[Tensor]:
    """[batch, C, h, w] -> the grid's tiles row by row, edge-padded (``mode``) to fill it."""
    th, tw = tile
    ph, pw = grid[0] * th - x.shape[2], grid[1] * tw - x.shape[3]
    if ph or pw:
        x = F.pad(x, (0, pw, 0, ph), mode=mode)
    return [
        x[:, :, r * th : (r + 1) * th, c * tw : (c + 1) * tw]
        for r in range(grid[0])
        for c in range(grid[1])
    ]


def fit_encode(
    codec, images: Tensor, snr_db, cbr: float, mask: Tensor | None = None, demand_weights=None
) -> Encoded:
    """``codec.encode`` for an image of any size.

    A codec that declares an input size or multiple gets the image edge-padded and cut into
    tiles it takes (object masks zero-padded alike); each tile is encoded at the rate that
    spreads the image's symbol budget (:func:`semcodec.contract.protocol.symbol_budget`) over the
    padded tiles, rounded down to the codec's ``symbol_multiple`` and held inside its
    ``cbr_range``; the tiles' unit-power symbols are sent one after another.

    Returns:
        :class:`Encoded`, its ``meta`` a :class:`TiledMeta` when the image was tiled.
    """
    x = check_images(images)
    b, _, h, w = x.shape
    plan = tiling(codec, h, w)
    if plan is None:
        return codec.encode(x, snr_db, cbr, mask=mask, demand_weights=demand_weights)
    (th, tw), grid = plan
    count = grid[0] * grid[1]
    step = codec_limits(codec).symbol_multiple
    per_tile = max(symbol_budget(cbr, h, w) // count // step * step, step)
    lo, hi = codec.cbr_range
    tile_cbr = min(max(per_tile / (3 * th * tw), lo), hi)
    masks = [None] * count if mask is None else _tiles(mask.float(), (th, tw), grid, "constant")
    encs = []
    for t, m in zip(_tiles(x, (th, tw), grid, "replicate"), masks):
        kw = {} if m is None else {"mask": m, "demand_weights": demand_weights}
        encs.append(codec.encode(t.contiguous(), snr_db, tile_cbr, **kw))
    sym = torch.cat([e.symbols for e in encs], dim=1).to(torch.complex64)
    meta = TiledMeta(
        inner=tuple(e.meta for e in encs),
        height=h,
        width=w,
        tile=(th, tw),
        grid=grid,
        num_symbols=int(sym.shape[1]),
        cbr=int(sym.shape[1]) / (3 * h * w),
        codec_sha256=encs[0].meta.codec_sha256,
    )
    return Encoded(sym, meta)


def _own_decode(codec, x_hat, meta, snr_db, expected_sha256, noise_var, differentiable: bool):
    if differentiable:
        snr = snr_per_image(snr_db, x_hat.shape[0])
        return codec.decode_differentiable(x_hat, meta, snr, noise_var)
    return codec.decode(x_hat, meta, snr_db, expected_sha256=expected_sha256, noise_var=noise_var)


def fit_decode(
    codec,
    x_hat: Tensor,
    meta,
    snr_db,
    expected_sha256=None,
    noise_var=None,
    differentiable: bool = False,
) -> Tensor:
    """Receiver of :func:`fit_encode`: the codec's ``decode`` (``decode_differentiable``
    with ``differentiable``) of each tile, the tiles put back together and cropped to the
    image: [batch, 3, height, width] float32."""
    if not isinstance(meta, TiledMeta):
        return _own_decode(codec, x_hat, meta, snr_db, expected_sha256, noise_var, differentiable)
    nv = None if noise_var is None else torch.as_tensor(noise_var, dtype=torch.float32)
    per_symbol = nv is not None and nv.dim() == 2 and nv.shape[-1] == x_hat.shape[-1]
    rows, at = [], 0
    for r in range(meta.grid[0]):
        row = []
        for c in range(meta.grid[1]):
            inner = meta.inner[r * meta.grid[1] + c]
            n = int(inner.num_symbols)
            part_nv = nv[:, at : at + n] if per_symbol and nv is not None else noise_var
            row.append(
                _own_decode(
                    codec,
                    x_hat[:, at : at + n],
                    inner,
                    snr_db,
                    expected_sha256,
                    part_nv,
                    differentiable,
                )
            )
            at += n
        rows.append(torch.cat(row, dim=3))
    return torch.cat(rows, dim=2)[:, :, : meta.height, : meta.width]
