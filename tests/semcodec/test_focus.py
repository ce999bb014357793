"""On-demand focus: the demand map, position selection, and that the heat map follows the object."""

import pytest
import torch

from semcodec import demand_weight_map, select_positions
from semcodec.focus import attribution_box, demand_positions


def test_demand_weight_map_is_lambda_weighted_mean():
    mask = torch.zeros(1, 2, 4, 4)
    mask[0, 0, :2] = 1  # object 0: top half
    mask[0, 1, :, :2] = 1  # object 1: left half
    w = demand_weight_map(mask, [3.0, 1.0], 1, 4, 4)[0, 0]
    assert w[0, 0] == pytest.approx(1.0)  # both
    assert w[0, 3] == pytest.approx(0.75)  # only object 0
    assert w[3, 0] == pytest.approx(0.25)  # only object 1
    assert w[3, 3] == 0.0
    empty = demand_weight_map(torch.zeros(1, 1, 4, 4), None, 1, 4, 4)
    assert torch.all(empty == 1.0)  # object not visible: whole image
    with pytest.raises(ValueError, match="demand_weights"):
        demand_weight_map(mask, [1.0, 2.0, 3.0], 1, 4, 4)
    with pytest.raises(ValueError, match="mask"):
        demand_weight_map(torch.zeros(1, 1, 5, 4), None, 1, 4, 4)


def test_select_positions_top_k_sorted():
    heat = torch.tensor([[[0.1, 5.0], [3.0, 0.2]]])
    assert select_positions(heat, 2).tolist() == [[1, 2]]
    with pytest.raises(ValueError, match="k"):
        select_positions(heat, 5)


def test_attribution_box_cuts_the_thin_tail():
    heat = torch.full((1, 6, 8), 0.001)
    heat[0, 1:3, 2:5] = 1.0
    heat[0, 4, 6] = 0.2
    assert attribution_box(heat, 0.05) == (1, 2, 4, 5)  # rows 1..4, cols 2..6
    assert attribution_box(heat, 0.5) == (1, 2, 2, 3)
    assert attribution_box(torch.zeros(1, 3, 3), 0.05) == (0, 0, 3, 3)


def test_the_box_keeps_every_position_showing_a_demanded_object():
    # a peaky attribution on the object's lower part must not cut its top off
    mask = torch.zeros(1, 2, 22, 24)  # padded to 24 x 24: a 6 x 6 feature grid
    mask[0, 0, 3:12, 9:14] = 1.0  # object 0: rows 3..11 -> positions 0..2, cols 9..13 -> 2..3
    mask[0, 0, 4, 20] = 0.4  # a soft edge below half: not the object
    mask[0, 1, 18:22, 0:4] = 1.0  # object 1, weight 0: not demanded
    pos = demand_positions(mask, [1.0, 0.0], (24, 24))
    want = torch.zeros(1, 6, 6, dtype=torch.bool)
    want[0, 0:3, 2:4] = True
    assert torch.equal(pos, want)
    heat = torch.zeros(1, 6, 6)
    heat[0, 2, 2:4] = 1.0
    assert attribution_box(heat, 0.05) == (2, 2, 1, 2)
    assert attribution_box(heat, 0.05, pos) == (0, 2, 3, 2)
    # equal weights: both objects are in
    assert demand_positions(mask, None, (24, 24))[0, 5, 0]


def _object_scene():
    g = torch.Generator().manual_seed(0)
    x = torch.rand(1, 3, 64, 64, generator=g)
    mask = torch.zeros(1, 1, 64, 64)
    mask[..., 8:40, :24] = 1  # object: rows 8..39, columns 0..23
    return x, mask


def test_focus_sends_the_object_box_within_budget(tiny_codec):
    x, mask = _object_scene()
    cbr = 1 / 16
    budget = round(cbr * 3 * 64 * 64)
    enc = tiny_codec.encode(x, 5.0, cbr, mask=mask, demand_weights=[1.0])
    top, left, h, w = enc.meta.crop
    assert h % 4 == 0 and w % 4 == 0 and h * w < 64 * 64  # something was dropped
    assert top <= 8 and left == 0 and top + h >= 40 and w >= 24  # the object is inside
    m = enc.meta.num_channels
    assert (
        m == min(8, budget // (h * w // 16)) and enc.symbols.shape[1] == m * h * w // 16 <= budget
    )
    torch.testing.assert_close((enc.symbols.abs() ** 2).mean(), torch.tensor(1.0))
    y = tiny_codec.decode(enc.symbols, enc.meta, 5.0)
    assert y.shape == x.shape
    assert torch.all(y[..., :, left + w :] == 0.5)  # nothing was sent there


def test_focus_below_one_channel_sends_top_positions(tiny_codec):
    x, mask = _object_scene()
    enc = tiny_codec.encode(x, 5.0, 1 / 600, mask=mask)
    budget = round(3 * 64 * 64 / 600)
    assert enc.meta.crop is None and enc.meta.num_channels == 1
    assert enc.symbols.shape[1] == enc.meta.positions.shape[1] == budget
    cols = enc.meta.positions[0] % 16
    assert float((cols <= 8).float().mean()) >= 0.75  # chance: 9/16
    assert tiny_codec.decode(enc.symbols, enc.meta, 5.0).shape == x.shape
