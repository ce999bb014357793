"""The side information our codec sends beside its symbols (:class:`EncodedMeta`), and
what both ends derive from it: where a focus box's partial channel goes
(:func:`centre_first`) and which pixels a focus box covers (:func:`receiver_mask`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from semcodec.contract.protocol import box_bits
from semcodec.jscc.analog import AnalogSide


@dataclass(frozen=True)
class EncodedMeta:
    """What the receiver needs besides the symbols (side information).

    Attributes:
        height, width: original image size in pixels.
        num_channels: complex channels kept per sent position (m). In focus mode a model
            whose decoder reads each symbol's reliability also sends channel m + 1 at the
            box's first ``num_symbols - m * positions`` positions of :func:`centre_first`
            (the budget's remainder; no side information needed).
        cbr: CBR actually used: num_symbols / (3 * height * width).
        num_symbols: complex symbols per image.
        codec_sha256: hash of the transmitter's codec (knowledge base identity).
        crop: (top, left, height, width) in pixels of the box sent in focus mode (the
            positions holding the demand's attribution), else None (whole image).
        analog: the analog refinement layer's side information when the last
            ``analog.num_symbols`` symbols carry the base's residual
            (:mod:`semcodec.jscc.analog`), else None.
    """

    height: int
    width: int
    num_channels: int
    cbr: float
    num_symbols: int
    codec_sha256: str
    crop: tuple[int, int, int, int] | None = None
    analog: AnalogSide | None = None

    @property
    def base_symbols(self) -> int:
        """Symbols of the learned channels (the first ones; the analog layer's follow)."""
        return self.num_symbols - (self.analog.num_symbols if self.analog is not None else 0)

    def side_info_bits(self) -> int:
        """Bits of side information per image: the focus box, plus the analog layer's
        chunk energies."""
        layer = self.analog.side_info_bits() if self.analog is not None else 0
        box = box_bits(self.height, self.width) if self.crop is not None else 0
        return box + layer


def centre_first(rows: int, cols: int) -> Tensor:
    """The positions of a rows x cols box (row-major indices), nearest its centre first
    (ties in row-major order): where a partial channel goes, known to both ends."""
    r, c = torch.meshgrid(torch.arange(rows), torch.arange(cols), indexing="ij")
    d = (2 * r - (rows - 1)) ** 2 + (2 * c - (cols - 1)) ** 2
    return torch.sort(d.flatten(), stable=True).indices


def receiver_mask(meta: EncodedMeta, height: int, width: int) -> np.ndarray | None:
    """[height, width] float32: the pixels the focus-mode side information says were sent
    (the ``meta.crop`` box); None = whole image."""
    if meta.crop is None:
        return None
    top, left, rows, cols = (int(v) for v in meta.crop)
    m = np.zeros((height, width), np.float32)
    m[max(top, 0) : min(top + rows, height), max(left, 0) : min(left + cols, width)] = 1.0
    return m
