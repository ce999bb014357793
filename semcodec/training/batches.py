"""Each training step's batch and channel noise, a function of the seed and the step alone.

Random streams (what makes a run resumable at another world size): step k's global batch
(crops, flips, SNRs, rates, channel) is drawn from ``numpy.random.default_rng([seed, k])``
whatever the world size, and rank r's channel noise from a torch generator seeded with
``SeedSequence([seed, k, r])``. A training state therefore needs no RNG state: the step
number and the weights define the rest. Runs at different world sizes see the same images,
SNRs and rates in the same order; they differ in the noise draws and in the order of the
gradient reduction's float sums.
"""

from __future__ import annotations

import numpy as np
import torch

from semcodec.training.config import TrainConfig
from semcodec.training.data import random_crops


def draw_batch(cfg: TrainConfig, images, levels, channels, step: int, rank: int, world: int):
    """Step ``step``'s global batch, drawn from ``default_rng([seed, step])``, and rank
    ``rank``'s share of it.

    Returns:
        (crops [batch_size / world, 3, crop_px, crop_px] float32, SNR [batch_size / world]
        float32 dB, CBR [batch_size / world] float32, channel name).
    """
    rng = np.random.default_rng([cfg.seed, step])
    b = cfg.batch_size
    x = random_crops(images, b, cfg.crop_px, rng)
    wide = rng.random(b) < cfg.p_wide_snr
    snr = np.where(
        wide,
        rng.uniform(cfg.snr_min_db, cfg.snr_max_db, b),
        rng.uniform(cfg.focus_snr_min_db, cfg.focus_snr_max_db, b),
    )
    k = len(levels)
    idx = np.where(rng.random(b) < cfg.p_focus_m, min(cfg.focus_m, k) - 1, rng.integers(0, k, b))
    channel = channels[int(rng.integers(len(channels)))] if len(channels) > 1 else channels[0]
    lo, hi = rank * b // world, (rank + 1) * b // world
    cbr = torch.tensor(np.asarray(levels)[idx], dtype=torch.float32)
    return x[lo:hi], torch.tensor(snr, dtype=torch.float32)[lo:hi], cbr[lo:hi], channel


def noise_generator(cfg: TrainConfig, step: int, rank: int, device) -> torch.Generator:
    """Rank ``rank``'s channel-noise generator at step ``step``: seeded by
    ``SeedSequence([seed, step, rank])``."""
    s = int(np.random.SeedSequence([cfg.seed, step, rank]).generate_state(1, np.uint64)[0])
    return torch.Generator(device=device).manual_seed(s & (2**63 - 1))
