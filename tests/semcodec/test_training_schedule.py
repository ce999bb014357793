"""The trainer's learning-rate schedule and the device of its channel mask."""

import math

import pytest
import torch

from semcodec.jscc.channels import channel_mask
from semcodec.training.loop import TrainConfig, lr_at


def test_warmup_is_linear_then_constant_then_cosine_to_a_twentieth():
    cfg = TrainConfig(lr=1e-3, max_steps=1000, warmup_steps=100, decay_fraction=0.5)
    assert lr_at(cfg, 0.0, 0) == pytest.approx(1e-5)
    assert lr_at(cfg, 0.0, 49) == pytest.approx(5e-4)
    assert lr_at(cfg, 0.0, 99) == pytest.approx(1e-3)
    assert lr_at(cfg, 0.0, 400) == pytest.approx(1e-3)
    # halfway through the decay: 0.05 + 0.95 * (1 + cos(pi / 2)) / 2 of the peak
    assert lr_at(cfg, 0.0, 750) == pytest.approx(1e-3 * (0.05 + 0.95 * 0.5))
    assert lr_at(cfg, 0.0, 1000) == pytest.approx(1e-3 * 0.05)


def test_no_warmup_by_default_and_wall_clock_decay():
    cfg = TrainConfig(lr=2e-4, max_minutes=10.0, decay_fraction=0.35)
    assert cfg.warmup_steps == 0
    assert lr_at(cfg, 0.0, 0) == pytest.approx(2e-4)
    t = (1.0 - 0.35 / 2) * 600.0
    assert lr_at(cfg, t, 5) == pytest.approx(
        2e-4 * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi / 2)))
    )


def test_warmup_steps_out_of_range_is_refused_by_name():
    with pytest.raises(ValueError, match="warmup_steps"):
        TrainConfig(warmup_steps=-1)


def test_channel_mask_lives_on_the_device_of_the_rates():
    m = torch.tensor([1, 3], device="meta")
    mask = channel_mask(m, 4)
    assert mask.device.type == "meta" and mask.shape == (2, 8, 1, 1)
    cpu = channel_mask(torch.tensor([1, 3]), 4)[:, :, 0, 0]
    assert cpu.tolist() == [[1, 1, 0, 0, 0, 0, 0, 0], [1, 1, 1, 1, 1, 1, 0, 0]]
