"""Test images for the codec tests: smooth random pictures (bilinear upsampling of noise)."""

from pathlib import Path

import numpy as np
import torch
from PIL import Image


def smooth_image(seed: int = 0, h: int = 32, w: int = 32) -> torch.Tensor:
    """[1, 3, h, w] float32 in [0, 1]: uniform noise at 1/8 resolution upsampled bilinearly."""
    g = torch.Generator().manual_seed(seed)
    base = torch.rand(1, 3, h // 8, w // 8, generator=g)
    return torch.nn.functional.interpolate(
        base, size=(h, w), mode="bilinear", align_corners=False
    ).clamp(0, 1)


def write_images(folder: Path, n: int, side: int, seed: int) -> Path:
    """``n`` smooth PNGs of ``side`` px in a new ``folder`` (named 0.png, 1.png, ...)."""
    folder.mkdir(parents=True)
    for i in range(n):
        a = smooth_image(seed + i, side, side)[0].permute(1, 2, 0).numpy()
        Image.fromarray(np.round(a * 255).astype(np.uint8)).save(folder / f"{i}.png")
    return folder
