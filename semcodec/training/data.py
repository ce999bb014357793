"""Training data: image folders, random crops (the trainer's per-step draws), the data hash.

Images are kept as [3, height, width] uint8 tensors; crops are float32 in [0, 1].
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import torch

from common import list_images, read_image, to_chw


def load_uint8_images(paths: list[Path]) -> list[torch.Tensor]:
    """RGB images (:func:`common.read_image`: 16-bit, palette, EXIF orientation) as
    [3, height, width] uint8 tensors."""
    return [to_chw(np.round(read_image(p) * 255.0).astype(np.uint8)) for p in paths]


def files_sha256(paths: list[Path]) -> str:
    """sha256 over the names and bytes of the training files (recorded in the model card)."""
    h = hashlib.sha256()
    for p in paths:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def random_crops(
    images: list[torch.Tensor], n: int, crop_px: int, rng: np.random.Generator
) -> torch.Tensor:
    """[n, 3, crop_px, crop_px] float32 in [0, 1]: random image, position and horizontal flip."""
    out = torch.empty(n, 3, crop_px, crop_px)
    for i in range(n):
        img = images[rng.integers(len(images))]
        _, h, w = img.shape
        y, x = rng.integers(h - crop_px + 1), rng.integers(w - crop_px + 1)
        c = img[:, y : y + crop_px, x : x + crop_px]
        if rng.random() < 0.5:
            c = c.flip(-1)
        if rng.random() < 0.5 and crop_px <= min(h, w):
            c = c.transpose(1, 2)
        out[i] = c.float() / 255.0
    return out


def load_data(crop_px: int, train_dirs: list[Path], val_dir: Path | None):
    """Training images ([3, height, width] uint8, those at least ``crop_px`` a side), their paths
    and hash, and up to 8 validation images cropped to one square side (<= 256 px, multiple of 4)
    or None."""
    paths = [p for d in train_dirs for p in list_images(d, "--data")]
    images = [im for im in load_uint8_images(paths) if min(im.shape[1:]) >= crop_px]
    if not images:
        raise ValueError(
            f"crop_px: no training image is at least {crop_px}x{crop_px} px "
            f"(of {len(paths)} images in {', '.join(str(d) for d in train_dirs)})"
        )
    val = None
    if val_dir is not None:
        vimgs = load_uint8_images(list_images(val_dir, "--val")[:8])
        if vimgs:
            side = min(256, min(min(im.shape[1:]) for im in vimgs) // 4 * 4)
            val = torch.stack([im[:, :side, :side].float() / 255 for im in vimgs])
    return images, paths, files_sha256(paths), val
