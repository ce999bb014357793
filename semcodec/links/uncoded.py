"""The analog baseline: uncoded pixels. Each image's values standardised (mean and std sent
as side information), paired into complex symbols, LMMSE-scaled at the receiver."""

from __future__ import annotations

import math

import torch
from torch import Tensor
from torch.nn import functional as F

from semcodec.contract.protocol import check_images
from semcodec.contract.transmit import TransmitResult, check_num_symbols, run_link


def transmit_analog(
    images: Tensor,
    link,
    snr_db,
    num_symbols: int | None = None,
    generator: torch.Generator | None = None,
) -> TransmitResult:
    """Uncoded pixels: two real values per complex symbol, LMMSE at the receiver.

    Args:
        num_symbols: symbols per image; None = all pixels (CBR 1/2). Fewer: the image is
            area-downsampled to fit and bilinearly upsampled at the receiver.
    """
    x = check_images(images)
    b, _, h, w = x.shape
    src = x
    if num_symbols is not None:
        n = check_num_symbols(num_symbols)
        scale = min(1.0, math.sqrt(2 * n / (3 * h * w)))
        hs, ws = max(1, int(h * scale)), max(1, int(w * scale))
        while 3 * hs * ws > 2 * n and hs > 1:
            hs -= 1
        src = F.interpolate(x, size=(hs, ws), mode="area") if (hs, ws) != (h, w) else x
    flat = src.reshape(b, -1)
    if flat.shape[1] % 2:
        flat = F.pad(flat, (0, 1), value=float(flat.mean()))
    mean = flat.mean(dim=1, keepdim=True)
    std = flat.std(dim=1, keepdim=True, unbiased=False).clamp_min(1e-6)
    s = (flat - mean) / std  # unit variance per real value
    sym = torch.view_as_complex(
        (s * math.sqrt(0.5)).reshape(b, -1, 2).contiguous()
    )  # mean |x|^2 = 1
    with torch.no_grad():
        x_hat, nv = run_link(link, sym, snr_db, generator)
    est = (
        x_hat / (1.0 + nv) * math.sqrt(2.0)
    )  # LMMSE for a unit-power source, back to unit variance
    v = torch.view_as_real(est.to(torch.complex64)).reshape(b, -1)[:, : src[0].numel()] * std + mean
    rec = v.reshape(src.shape)
    if rec.shape[-2:] != (h, w):
        rec = F.interpolate(rec, size=(h, w), mode="bilinear", align_corners=False)
    return TransmitResult(rec.clamp(0, 1), {"num_symbols": sym.shape[1] * b, "failed_codewords": 0})
