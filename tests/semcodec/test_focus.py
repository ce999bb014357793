"""On-demand focus: the demand map, the box and its densest part, and that the heat map follows the
object."""

import pytest
import torch

from semcodec.contract import box_side_symbols
from semcodec.jscc import demand_weight_map, densest_box, learned_only
from semcodec.jscc.focus import attribution_box, demand_positions


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


def test_densest_box_keeps_the_shape_and_the_most_attribution():
    heat = torch.zeros(2, 6, 8)
    heat[0, 3, 5] = 1.0  # the two images' heat adds up
    heat[1, 4, 6] = 2.0
    box = (0, 0, 6, 8)
    assert densest_box(heat, box, 48) == box  # it fits already
    # 12 of 48 positions: half the rows and cols, 3 x 4; the first 3 x 4 window over both
    # hot positions (rows 3..4, cols 5..6) starts at row 2, col 3
    assert densest_box(heat, box, 12) == (2, 3, 3, 4)
    assert densest_box(heat, (3, 4, 2, 4), 2) == (4, 5, 1, 2)  # the first 1 x 2 holding 2.0
    assert densest_box(heat, box, 1) == (4, 6, 1, 1)
    with pytest.raises(ValueError, match="max_positions"):
        densest_box(heat, box, 0)


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
    pos = demand_positions(mask, [1.0, 0.0], (22, 24), (24, 24))
    want = torch.zeros(1, 6, 6, dtype=torch.bool)
    want[0, 0:3, 2:4] = True
    assert torch.equal(pos, want)
    heat = torch.zeros(1, 6, 6)
    heat[0, 2, 2:4] = 1.0
    assert attribution_box(heat, 0.05) == (2, 2, 1, 2)
    assert attribution_box(heat, 0.05, pos) == (0, 2, 3, 2)
    # equal weights: both objects are in
    assert demand_positions(mask, None, (22, 24), (24, 24))[0, 5, 0]


def _object_scene():
    g = torch.Generator().manual_seed(0)
    x = torch.rand(1, 3, 64, 64, generator=g)
    mask = torch.zeros(1, 1, 64, 64)
    mask[..., 8:40, :24] = 1  # object: rows 8..39, columns 0..23
    return x, mask


def test_focus_sends_the_object_box_within_budget(tiny_codec):
    x, mask = _object_scene()
    cbr = 1 / 16
    budget = round(cbr * 3 * 64 * 64) - box_side_symbols(64, 64)  # the box's side information
    # learned channels only: on noise, an untrained model's decode loses to the analog layer
    enc = learned_only(tiny_codec).encode(x, 5.0, cbr, mask=mask, demand_weights=[1.0])
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


def test_focus_below_one_channel_sends_the_densest_part_of_the_box(tiny_codec):
    """A budget below one channel over the object's box sends the part of the box that holds
    the most attribution, one channel on each position; its side information is still only
    the box, charged to the budget. A budget that cannot carry the box is refused."""
    x, mask = _object_scene()
    full = learned_only(tiny_codec).encode(x, 5.0, 1 / 16, mask=mask)
    budget = round(3 * 64 * 64 / 150) - box_side_symbols(64, 64)
    enc = learned_only(tiny_codec).encode(x, 5.0, 1 / 150, mask=mask)
    top, left, h, w = enc.meta.crop
    t0, l0, h0, w0 = full.meta.crop
    assert enc.meta.num_channels == 1 and h * w // 16 <= budget < h0 * w0 // 16
    assert t0 <= top and l0 <= left and top + h <= t0 + h0 and left + w <= l0 + w0
    assert enc.symbols.shape[1] <= budget
    assert enc.meta.side_info_bits() == full.meta.side_info_bits()  # the box, nothing more
    assert tiny_codec.decode(enc.symbols, enc.meta, 5.0).shape == x.shape
    with pytest.raises(ValueError, match="side information"):
        tiny_codec.encode(x, 5.0, box_side_symbols(64, 64) / (3 * 64 * 64), mask=mask)


def test_centre_first_orders_a_box_from_its_centre_out():
    from semcodec.jscc.encoded_meta import centre_first

    # 3 x 4 box, centre (1, 1.5): the two middle cells, then the four beside them
    # vertically, then the row ends, then the corners (ties row-major)
    assert centre_first(3, 4).tolist() == [5, 6, 1, 2, 9, 10, 4, 7, 0, 3, 8, 11]


def test_focus_spends_the_whole_budget_with_a_partial_channel_for_v2_models():
    """A reliability-aware decoder gets channel m + 1 at the box's central positions (the
    rest of that channel looks erased to it), so the focus budget is spent to the symbol:
    the box's side information and the symbols fill it."""
    from semcodec.contract import box_side_symbols
    from semcodec.jscc import Codec, make_model
    from semcodec.jscc.encoded_meta import centre_first
    from semcodec.jscc.model import features_to_symbols, side_info, symbols_to_features

    torch.manual_seed(1)
    model = make_model("adjscc_s4_w96_rel")
    codec = Codec(model, {"sha256": "t" * 64, "name": "tiny-v2"})
    x, mask = _object_scene()
    cbr, snr = 1 / 40, 5.0
    budget = round(cbr * 3 * 64 * 64) - box_side_symbols(64, 64)
    assert box_side_symbols(64, 64) == 40  # 4 x 5 bits (0..16 in 4 px units) at 0.5 bit/symbol
    enc = codec.encode(x, snr, cbr, mask=mask, demand_weights=[1.0])
    top, left, h, w = enc.meta.crop
    rows, cols, m = h // 4, w // 4, enc.meta.num_channels
    n, extra = m * rows * cols, budget - m * rows * cols
    assert m == budget // (rows * cols) < 8 and extra > 0
    assert enc.symbols.shape[1] == enc.meta.num_symbols == budget
    torch.testing.assert_close((enc.symbols.abs() ** 2).mean(), torch.tensor(1.0))
    # the symbols are the encoder's m + 1 channels of the box, the last at centre_first
    with torch.no_grad():
        fc = model.encoder(x[..., top : top + h, left : left + w], side_info(snr, m + 1, 8, 1))
    raw = torch.cat(
        [
            features_to_symbols(fc, m),
            features_to_symbols(fc[:, 2 * m : 2 * m + 2], 1)[:, centre_first(rows, cols)[:extra]],
        ],
        1,
    )
    k = enc.symbols.abs().pow(2).sum() / raw.abs().pow(2).sum()
    torch.testing.assert_close(enc.symbols, raw * k.sqrt(), rtol=1e-4, atol=1e-5)
    # the receiver puts them back there: the same image as the decoder fed by hand
    y = codec.decode(enc.symbols, enc.meta, snr)
    rel = 1.0 / (1.0 + 10 ** (-snr / 10))
    part = torch.zeros(1, rows * cols, dtype=torch.complex64)
    part[:, centre_first(rows, cols)[:extra]] = enc.symbols[:, n:]
    z = symbols_to_features(enc.symbols[:, :n] * rel, m, 8, rows, cols)
    z[:, 2 * m : 2 * m + 2] = symbols_to_features(part * rel, 1, 1, rows, cols)
    r = torch.zeros(1, 8, rows, cols)
    r[:, :m] = rel
    r[:, m].view(1, -1)[:, centre_first(rows, cols)[:extra]] = rel
    with torch.no_grad():
        by_hand = model.decoder(z, side_info(snr, m + 1, 8, 1), r).clamp(0, 1)
    torch.testing.assert_close(y[..., top : top + h, left : left + w], by_hand)
