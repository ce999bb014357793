"""The one PSNR and its edge cases (identical images, NaN, masks, range), decided once."""

import math

import numpy as np
import pytest
import torch

from common import PSNR_MAX_DB, psnr


def test_psnr_against_the_formula():
    x = np.zeros((4, 4, 3))
    y = np.full((4, 4, 3), 0.1)
    assert psnr(x, y) == pytest.approx(20.0)  # mse 0.01
    assert psnr(torch.zeros(1, 3, 4, 4), torch.full((1, 3, 4, 4), 0.1)) == pytest.approx(20.0)


def test_identical_images_give_the_finite_cap_and_one_level_scores_below_it():
    x = np.random.default_rng(0).random((8, 8, 3))
    assert psnr(x, x) == PSNR_MAX_DB
    y = x.copy()
    y[0, 0, 0] += 1 / 65535
    assert psnr(x, y) < PSNR_MAX_DB


def test_nan_gives_nan_and_values_are_clipped_to_the_display_range():
    x = np.zeros((2, 2, 3))
    y = x.copy()
    y[0, 0, 0] = math.nan
    assert math.isnan(psnr(x, y))
    assert psnr(np.full((2, 2, 3), 1.7), np.ones((2, 2, 3))) == PSNR_MAX_DB


def test_mask_scores_only_its_pixels_and_an_empty_mask_is_nan():
    x = np.zeros((2, 2, 3))
    y = np.zeros((2, 2, 3))
    y[0, 0] = 0.1
    mask = np.zeros((2, 2, 1))
    mask[0, 0] = 1
    assert psnr(x, y, mask) == pytest.approx(20.0)
    assert math.isnan(psnr(x, y, np.zeros((2, 2, 1))))
    with pytest.raises(ValueError, match="shape"):
        psnr(x, y[:1])
