"""The one MS-SSIM (common.ms_ssim): pytorch-msssim's five scales, the prediction clipped."""

import numpy as np
import pytest
import torch

from common import MS_SSIM_MIN_SIDE_PX, ms_ssim


def _pair(side: int, noise: float):
    g = torch.Generator().manual_seed(0)
    y = torch.rand(1, 3, side, side, generator=g)
    return y + noise * torch.randn(y.shape, generator=g), y


def test_identical_images_score_one_and_noise_scores_less():
    x, y = _pair(192, 0.0)
    assert ms_ssim(x, y) == pytest.approx(1.0, abs=1e-6)
    a, _ = _pair(192, 0.05)
    b, _ = _pair(192, 0.2)
    assert 0 < ms_ssim(b, y) < ms_ssim(a, y) < 1


def test_it_is_pytorch_msssims_with_the_prediction_clipped():
    from pytorch_msssim import ms_ssim as reference

    x, y = _pair(176, 0.3)  # noise pushes values outside [0, 1]
    want = float(reference(x.clamp(0, 1), y, data_range=1.0, size_average=True))
    assert ms_ssim(x, y) == want
    assert ms_ssim(x[0].numpy(), y[0].numpy()) == want  # [3, H, W] numpy alike


def test_too_small_images_have_none_and_bad_shapes_are_refused():
    x, y = _pair(MS_SSIM_MIN_SIDE_PX - 1, 0.1)
    assert ms_ssim(x, y) is None
    with pytest.raises(ValueError, match="ms_ssim"):
        ms_ssim(np.zeros((200, 200, 3)), np.zeros((200, 200, 3)))
