"""Test images for the codec tests: smooth random pictures (bilinear upsampling of noise)."""

import torch


def smooth_image(seed: int = 0, h: int = 32, w: int = 32) -> torch.Tensor:
    """[1, 3, h, w] float32 in [0, 1]: uniform noise at 1/8 resolution upsampled bilinearly."""
    g = torch.Generator().manual_seed(seed)
    base = torch.rand(1, 3, h // 8, w // 8, generator=g)
    return torch.nn.functional.interpolate(
        base, size=(h, w), mode="bilinear", align_corners=False
    ).clamp(0, 1)
