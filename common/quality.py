"""The one PSNR (peak 1.0) and the one MS-SSIM of the project, for every package and command.

Edge cases, decided once:

* both images are clipped to [0, 1] first (what a display shows; decoders may overshoot);
* identical images give :data:`PSNR_MAX_DB` (120 dB, an MSE floor of 1e-12), a finite number
  that JSON and means can hold; any real difference of one 16-bit level scores below it;
* NaN anywhere in the compared pixels gives NaN (a diverged model is reported, not hidden);
* an empty mask gives NaN (there is nothing to score).
"""

from __future__ import annotations

import math

import numpy as np

PSNR_MAX_DB = 120.0
_MSE_FLOOR = 10.0 ** (-PSNR_MAX_DB / 10.0)


def _np(x) -> np.ndarray:
    if hasattr(x, "detach"):  # a torch tensor, without importing torch
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


def psnr(x, y, mask=None) -> float:
    """PSNR in dB (peak 1.0) of one image pair, over the pixels where ``mask`` > 0.5.

    Args:
        x, y: the same shape, any layout ([height, width, 3], [1, 3, height, width], ...),
            numpy arrays or torch tensors, values in [0, 1].
        mask: None (every pixel) or an array broadcastable to ``x``'s shape, e.g.
            [height, width, 1] for [height, width, 3] images, [1, 1, height, width] for
            [1, 3, height, width].
    Returns:
        -10 log10(MSE) as a float, at most :data:`PSNR_MAX_DB`; NaN for NaN input or an
        empty mask.
    """
    a, b = _np(x), _np(y)
    if a.shape != b.shape:
        raise ValueError(f"psnr: images differ in shape: {a.shape} and {b.shape}")
    d2 = (np.clip(a, 0.0, 1.0) - np.clip(b, 0.0, 1.0)) ** 2
    d2[np.isnan(a) | np.isnan(b)] = np.nan  # np.clip keeps NaN; make it explicit
    if mask is None:
        mse = float(d2.mean())
    else:
        m = np.broadcast_to(_np(mask) > 0.5, d2.shape)
        if not m.any():
            return math.nan
        mse = float(d2[m].mean())
    if math.isnan(mse):
        return math.nan
    return -10.0 * math.log10(max(mse, _MSE_FLOOR))


MS_SSIM_MIN_SIDE_PX = 161
"""The smallest side MS-SSIM's five scales with an 11-px window accept (pytorch-msssim:
more than (11 - 1) * 2^4 px)."""


def ms_ssim(x, y) -> float | None:
    """MS-SSIM of one image pair (pytorch-msssim: five scales, 11-px Gaussian window, data
    range 1.0; ``x`` clipped to [0, 1] as :func:`psnr` does).

    Args:
        x, y: [3, height, width] or [1, 3, height, width], numpy arrays or torch tensors.
    Returns:
        MS-SSIM in [0, 1], or None when a side is under :data:`MS_SSIM_MIN_SIDE_PX`.
    """
    import torch
    from pytorch_msssim import ms_ssim as _ms_ssim

    a = torch.as_tensor(np.asarray(x) if not hasattr(x, "detach") else x.detach().cpu())
    b = torch.as_tensor(np.asarray(y) if not hasattr(y, "detach") else y.detach().cpu())
    if a.shape != b.shape or a.dim() not in (3, 4) or a.shape[-3] != 3:
        raise ValueError(f"ms_ssim: need [1, 3, H, W] or [3, H, W] pairs, got {a.shape}, {b.shape}")
    if min(b.shape[-2:]) < MS_SSIM_MIN_SIDE_PX:
        return None
    a, b = (a[None] if a.dim() == 3 else a), (b[None] if b.dim() == 3 else b)
    with torch.no_grad():
        return float(_ms_ssim(a.clamp(0, 1).float(), b.float(), data_range=1.0, size_average=True))
