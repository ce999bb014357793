"""The one PSNR of the project (peak 1.0), for every package and command.

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
