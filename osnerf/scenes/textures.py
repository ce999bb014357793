"""Procedural albedo textures (numpy, seeded): enough detail for a radiance field to learn.

Every function returns [height, width, 3] float32 albedo in [0, 1] and repeats seamlessly.
"""

from __future__ import annotations

import numpy as np


def _noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Smooth tileable value noise: [size, size] float in [0, 1]."""
    grid = rng.random((cells, cells))
    t = np.arange(size) * cells / size
    i0 = np.floor(t).astype(int)
    f = t - i0
    f = f * f * (3 - 2 * f)
    i1 = (i0 + 1) % cells
    a = grid[np.ix_(i0, i0)] * (1 - f)[None, :] + grid[np.ix_(i0, i1)] * f[None, :]
    b = grid[np.ix_(i1, i0)] * (1 - f)[None, :] + grid[np.ix_(i1, i1)] * f[None, :]
    return a * (1 - f)[:, None] + b * f[:, None]


def bricks(seed: int = 0, size: int = 128) -> np.ndarray:
    """Red-brown bricks in running bond with grey mortar (4 rows x 2 bricks per tile)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    row = np.floor(y * 4).astype(int)
    xs = (x * 2 + 0.5 * (row % 2)) % 1.0
    mortar = (np.abs((y * 4) % 1.0 - 0.5) > 0.42) | (np.abs(xs - 0.5) > 0.46)
    brick_id = row * 3 + np.floor(x * 2 + 0.5 * (row % 2)).astype(int)
    tint = rng.uniform(0.75, 1.1, size=64)[brick_id % 64]
    base = np.stack([0.55 * tint, 0.22 * tint, 0.15 * tint], -1)
    base = base * (0.85 + 0.3 * _noise(rng, size, 16))[..., None]
    out = np.where(mortar[..., None], np.array([0.62, 0.6, 0.56]), base)
    return np.clip(out, 0, 1).astype(np.float32)


def painted_metal(
    seed: int = 1, size: int = 128, color=(0.75, 0.08, 0.06), band=(0.9, 0.75, 0.1)
) -> np.ndarray:
    """Fire-hydrant paint: a base colour with a band, bolts and wear."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    out = np.broadcast_to(np.array(color, np.float64), (size, size, 3)).copy()
    out[(y > 0.42) & (y < 0.58)] = band
    bolts = ((x * 8) % 1.0 - 0.5) ** 2 + ((y * 8) % 1.0 - 0.5) ** 2 < 0.03
    out[bolts] = (0.25, 0.25, 0.25)
    wear = _noise(rng, size, 8)
    out *= (0.8 + 0.35 * wear)[..., None]
    return np.clip(out, 0, 1).astype(np.float32)


def pavement(seed: int = 2, size: int = 128) -> np.ndarray:
    """Grey paving slabs (2 x 2 per tile) with joints and stains."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    joint = (np.abs((x * 2) % 1.0 - 0.5) > 0.47) | (np.abs((y * 2) % 1.0 - 0.5) > 0.47)
    slab = (np.floor(x * 2) + 2 * np.floor(y * 2)).astype(int)
    tint = rng.uniform(0.85, 1.1, size=4)[slab]
    base = 0.5 * tint * (0.8 + 0.35 * _noise(rng, size, 16))
    out = np.where(joint, 0.3, base)
    rgb = np.stack([out * 1.0, out * 0.98, out * 0.92], -1)
    return np.clip(rgb, 0, 1).astype(np.float32)


def roof_tiles(seed: int = 4, size: int = 128) -> np.ndarray:
    """Dark slate tiles in rows."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    row = np.floor(y * 8).astype(int)
    edge = ((y * 8) % 1.0) > 0.85
    xs = (x * 4 + 0.5 * (row % 2)) % 1.0
    vert = np.abs(xs - 0.5) > 0.47
    tint = rng.uniform(0.8, 1.15, size=(8, 5))[
        row, np.floor(x * 4 + 0.5 * (row % 2)).astype(int) % 5
    ]
    base = np.stack([0.22 * tint, 0.24 * tint, 0.3 * tint], -1)
    base[edge | vert] *= 0.5
    return np.clip(base, 0, 1).astype(np.float32)


def windows(seed: int = 5, size: int = 128, wall=(0.8, 0.74, 0.6)) -> np.ndarray:
    """A plastered wall with a 2 x 2 grid of windows per tile (facades)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    win = (np.abs((x * 2) % 1.0 - 0.5) < 0.22) & (np.abs((y * 2) % 1.0 - 0.5) < 0.28)
    frame = (np.abs((x * 2) % 1.0 - 0.5) < 0.26) & (np.abs((y * 2) % 1.0 - 0.5) < 0.32) & ~win
    out = np.broadcast_to(np.array(wall, np.float64), (size, size, 3)).copy()
    out *= (0.85 + 0.25 * _noise(rng, size, 16))[..., None]
    out[frame] = (0.9, 0.9, 0.88)
    out[win] = (0.12, 0.16, 0.22)
    return np.clip(out, 0, 1).astype(np.float32)


def bark(seed: int = 6, size: int = 64) -> np.ndarray:
    """Brown vertical bark stripes."""
    rng = np.random.default_rng(seed)
    n = _noise(rng, size, 16)
    stripes = 0.5 + 0.5 * np.sin(np.arange(size)[None, :] * 2 * np.pi * 6 / size + 3 * n)
    rgb = np.stack([0.3 + 0.1 * stripes, 0.2 + 0.06 * stripes, 0.1 + 0.03 * stripes], -1)
    return np.clip(rgb, 0, 1).astype(np.float32)


def foliage(seed: int = 7, size: int = 64) -> np.ndarray:
    """Dark and light green leaf clumps."""
    rng = np.random.default_rng(seed)
    n = 0.5 * _noise(rng, size, 8) + 0.5 * _noise(rng, size, 16)
    rgb = np.stack([0.08 + 0.12 * n, 0.25 + 0.35 * n, 0.06 + 0.08 * n], -1)
    return np.clip(rgb, 0, 1).astype(np.float32)
