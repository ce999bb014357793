"""The codec's feature grid in pixels: one feature position per ``BLOCK_PX`` square of the
(possibly upsampled) image. Which positions a mask touches, what fraction of the grid that
is, which pixels those positions cover, and how many symbols sending them all costs.

Shapes: masks [num_views, height, width] in [0, 1]; positions row-major on the
``ceil(height / BLOCK_PX) x ceil(width / BLOCK_PX)`` grid.
"""

from __future__ import annotations

import numpy as np

BLOCK_PX = 4
"""Side of the image square one feature position covers (the encoder's downsampling)."""


def full_rate_symbols(
    masks: np.ndarray,
    cbr_range: tuple[float, float],
    repetitions: np.ndarray,
    oversampling: int,
    block_px: int = BLOCK_PX,
) -> float:
    """Symbols of the on-demand views at the codec's largest CBR on every feature position
    touching the objects, upsampled by ``oversampling``, times their copies."""
    h, w = np.asarray(masks).shape[1:]
    cov = focus_coverage(masks, block_px, oversampling)
    s = oversampling
    return float(np.sum(cov * cbr_range[1] * (s * h) * (s * w) * 3 * np.asarray(repetitions)))


def focus_blocks(masks: np.ndarray, block_px: int = BLOCK_PX, oversampling: int = 1) -> np.ndarray:
    """The codec's feature positions (``block_px`` squares of the image upsampled by
    ``oversampling``) that touch the objects' mask (> 0.05).

    Args:
        masks: [num_views, height, width] in [0, 1].
    Returns:
        [num_views, ceil(s*height/block_px), ceil(s*width/block_px)] bool.
    """
    m = np.asarray(masks) > 0.05
    if oversampling > 1:
        m = m.repeat(oversampling, axis=1).repeat(oversampling, axis=2)
    n, h, w = m.shape
    hf, wf = -(-h // block_px), -(-w // block_px)
    pad = np.zeros((n, hf * block_px, wf * block_px), bool)
    pad[:, :h, :w] = m
    return pad.reshape(n, hf, block_px, wf, block_px).any((2, 4))


def focus_coverage(
    masks: np.ndarray, block_px: int = BLOCK_PX, oversampling: int = 1
) -> np.ndarray:
    """Fraction of the feature positions of :func:`focus_blocks` that touch the objects,
    per view: [num_views] float64 in [0, 1]."""
    return focus_blocks(masks, block_px, oversampling).mean((1, 2)).astype(np.float64)


def focus_pixel_masks(
    masks: np.ndarray, block_px: int = BLOCK_PX, oversampling: int = 1
) -> np.ndarray:
    """[num_views, height, width] float32: 1 on the pixels that the feature positions of
    :func:`focus_blocks` cover (at the captured resolution)."""
    n, h, w = np.asarray(masks).shape
    b = focus_blocks(masks, block_px, oversampling)
    px = b.repeat(block_px, axis=1).repeat(block_px, axis=2)[
        :, : oversampling * h, : oversampling * w
    ]
    return px.reshape(n, h, oversampling, w, oversampling).any((2, 4)).astype(np.float32)
