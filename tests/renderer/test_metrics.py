"""PSNR, SSIM and masked PSNR on hand-made images."""

import math

import numpy as np
import pytest
import torch

from renderer import image_metrics, masked_psnr, ssim


def test_masked_psnr_only_counts_the_mask():
    target = torch.zeros(4, 4, 3)
    pred = torch.zeros(4, 4, 3)
    pred[:, 2:] = 1.0  # wrong only outside the mask
    mask = torch.zeros(4, 4)
    mask[:, :2] = 1.0
    pred[:, :2] = 0.01  # MSE 1e-4 inside -> 40 dB
    assert math.isclose(masked_psnr(pred, target, mask), 40.0, rel_tol=1e-6)
    assert math.isnan(masked_psnr(pred, target, torch.zeros(4, 4)))


def test_ssim_identity_and_degradation():
    g = np.random.default_rng(0)
    img = g.random((32, 32, 3))
    assert ssim(img, img) == pytest.approx(1.0)
    noisy = np.clip(img + g.normal(0, 0.2, img.shape), 0, 1)
    assert ssim(noisy, img) < 0.9


def test_image_metrics_averages_per_view():
    target = torch.zeros(2, 8, 8, 3)
    pred = target.clone()
    pred[0] += 0.1  # 20 dB
    pred[1] += 0.01  # 40 dB
    m = image_metrics(pred, target, masks=torch.ones(2, 8, 8))
    assert m["num_views"] == 2
    assert m["psnr"] == pytest.approx(30.0)  # mean of per-view values, not PSNR of the mean MSE
    assert m["psnr_per_view"] == pytest.approx([20.0, 40.0])
    assert m["masked_psnr"] == pytest.approx(30.0)
    with pytest.raises(ValueError, match="shape"):
        image_metrics(pred, target[:1])
