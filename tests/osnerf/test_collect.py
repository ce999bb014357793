"""The on-demand collector and the semantic control unit, on synthetic views (no rendering)."""

from pathlib import Path

import numpy as np
import pytest

from osnerf.collect import CollectorConfig, Demand, collect, masked_images
from osnerf.scenes import SceneViews, intrinsics_from_fov
from osnerf.scu import KnowledgeBaseError, RatePolicy, SemanticControlUnit
from phy import CopyFading
from semcodec.contract import box_side_symbols
from semcodec.jscc.grid import focus_coverage, focus_pixel_masks


def synthetic_views(visible_hydrant, visible_tree, n_test=2, size=8):
    """Views where the hydrant covers a known square with the given visible fractions."""
    n = len(visible_hydrant) + n_test
    rng = np.random.default_rng(0)
    images = rng.random((n, size, size, 3)).astype(np.float32)
    masks = {
        "hydrant": np.zeros((n, size, size), np.float32),
        "tree": np.zeros((n, size, size), np.float32),
    }
    vis = {"hydrant": np.zeros(n), "tree": np.zeros(n)}
    for k, (vh, vt) in enumerate(zip(visible_hydrant, visible_tree)):
        if vh > 0:
            masks["hydrant"][k, 2:6, 2:6] = 1.0
        if vt > 0:
            masks["tree"][k, 0:2, :] = 1.0
        vis["hydrant"][k], vis["tree"][k] = vh, vt
    split = np.array(["train"] * len(visible_hydrant) + ["test"] * n_test)
    return SceneViews(
        folder=Path("."),
        images=images,
        poses=np.tile(np.eye(4), (n, 1, 1)),
        intrinsics=intrinsics_from_fov(40, size, size),
        split=split,
        masks=masks,
        visible_fraction=vis,
        pixel_fraction={o: masks[o].mean((1, 2)) for o in masks},
        drone_positions_m=np.zeros((n, 3)),
        meta={"objects": ["hydrant", "tree"], "background": [1.0, 1.0, 1.0]},
    )


def test_demand_parsing_and_weights():
    d = Demand.parse("hydrant:3, tree")
    assert d.objects == ("hydrant", "tree") and d.weights == pytest.approx((0.75, 0.25))
    for bad in ("", "hydrant:x", "hydrant:-1", "hydrant,hydrant"):
        with pytest.raises(ValueError):
            Demand.parse(bad)


def test_views_without_the_object_are_never_sent():
    views = synthetic_views([1.0, 0.0, 0.5, 0.9, 0.0], [0.0, 1.0, 1.0, 0.0, 0.0])
    col = collect(views, Demand.parse("hydrant"), CollectorConfig(min_visible_fraction=0.8))
    assert col.indices.tolist() == [0, 3]
    assert set(col.reasons) == {1, 2, 4}
    assert "hydrant: visible 0.50" in col.reasons[2]
    # what is sent holds nothing but the object: outside its mask every pixel is background
    assert np.all(col.images[:, :2] == 1.0) and np.all(col.images[:, 6:] == 1.0)
    np.testing.assert_array_equal(col.images[:, 2:6, 2:6], views.images[[0, 3], 2:6, 2:6])
    assert 5 not in col.indices and 6 not in col.indices  # held-out views are never candidates


def test_two_objects_union_and_per_object_masks():
    views = synthetic_views([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    col = collect(views, Demand.parse("hydrant:1,tree:3"))
    assert col.indices.tolist() == [0, 1]
    # one mask per demanded object, in the demand's order (the encoder's routing input)
    assert col.object_masks.shape[:2] == (2, 2)
    assert col.object_masks[1, 1, 0, 0] == 1.0 and col.object_masks[1, 0, 0, 0] == 0.0
    assert col.object_masks[0, 0, 3, 3] == 1.0
    assert col.masks[0].sum() == 16 and col.masks[1].sum() == 16


def test_no_camera_sees_the_demand_and_unknown_object():
    views = synthetic_views([0.1, 0.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="no drone camera sees the demanded object"):
        collect(views, Demand.parse("hydrant"))
    with pytest.raises(KeyError, match="known objects: hydrant, tree"):
        collect(views, Demand.parse("car"))


def test_masked_images_composite():
    img = np.full((1, 1, 2, 3), 0.2, np.float32)
    m = np.array([[[1.0, 0.25]]], np.float32)
    out = masked_images(img, m, np.array([1.0, 0.0, 0.5]))
    np.testing.assert_allclose(out[0, 0, 0], [0.2, 0.2, 0.2])
    np.testing.assert_allclose(out[0, 0, 1], [0.2 * 0.25 + 0.75, 0.05, 0.05 + 0.375])


def test_knowledge_base_refusal_is_logged():
    scu = SemanticControlUnit(Demand.parse("hydrant"))
    scu.check_knowledge_base("ab" * 32, "ab" * 32)
    with pytest.raises(KnowledgeBaseError, match="knowledge-base mismatch"):
        scu.check_knowledge_base("ab" * 32, "cd" * 32)
    assert [d["decision"] for d in scu.decisions] == ["agreed", "refused"]
    assert isinstance(KnowledgeBaseError("x"), ValueError)  # the CLI maps it to exit 2


def test_rate_policy_bands_and_clamp():
    p = RatePolicy(thresholds_db=(0.0, 10.0), cbrs=(1 / 6, 1 / 12, 1 / 24))
    assert p.cbr_for(-3) == pytest.approx(1 / 6)
    assert p.cbr_for(0.0) == pytest.approx(1 / 12)  # a threshold belongs to the band above
    assert p.cbr_for(15) == pytest.approx(1 / 24)
    scu = SemanticControlUnit(Demand.parse("hydrant"), rate_policy=p)
    cbr = scu.choose_cbr(np.array([-3.0, 15.0]), (1 / 16, 1 / 8), [4, 9])
    np.testing.assert_allclose(cbr, [1 / 8, 1 / 16])
    assert [d["view"] for d in scu.decisions] == [4, 9]
    with pytest.raises(ValueError, match="cbrs must have"):
        RatePolicy(thresholds_db=(0.0,), cbrs=(0.1,))


def test_focus_positions_at_each_oversampling():
    m = np.zeros((1, 8, 8), np.float32)
    m[0, 1, 1] = 1.0  # one pixel: 1 of the 2 x 2 feature positions
    assert focus_coverage(m)[0] == pytest.approx(1 / 4)
    # upsampled twice it covers pixels 2..3 of 16: still one position, now of 4 x 4
    assert focus_coverage(m, oversampling=2)[0] == pytest.approx(1 / 16)
    m[0, 5, 6] = 0.04  # below the 0.05 mask threshold: not a demand
    assert focus_coverage(m)[0] == pytest.approx(1 / 4)
    px = focus_pixel_masks(m)
    assert px.sum() == 16 and px[0, :4, :4].all()
    px2 = focus_pixel_masks(m, oversampling=2)  # 4 x 4 block of the 16 px image = 2 x 2 here
    assert px2.sum() == 4 and px2[0, :2, :2].all()


def test_oversampling_spends_the_saved_symbols_within_the_budget():
    """An 8 x 8 pixel object in 16 x 16 views: a quarter of the feature positions at every
    oversampling s, so the full rate is cbr 1/6 * 1/4 = 1/24 and costs 1/24 * (16 s)^2 * 3
    symbols per copy: 32, 128, 288 at s = 1, 2, 3; 4 copies in all."""
    m = np.zeros((3, 16, 16), np.float32)
    m[:, 4:12, 4:12] = 1.0
    reps = np.array([2, 1, 1])
    full = {1: 128, 2: 512, 3: 1152}
    cbr_range = (1 / 48, 1 / 6)
    scu = SemanticControlUnit(Demand.parse("hydrant"))  # 2/3 of the full scene, 0.09 CBR
    # per position = 0.54 of the full rate at CBR 1/6
    # budget 360: s = 3 would get 0.31 of its full rate, s = 2 0.70 of it
    assert scu.choose_oversampling(m, cbr_range, reps, full_scene_symbols=540) == (
        2,
        pytest.approx(360 / 512),
    )
    assert scu.decisions[-1]["full_rate_symbols_by_oversampling"] == {
        str(k): full[k] for k in (2, 3)
    }
    # budget 600: s = 3 would get 0.52 of its full rate (0.087 per position), s = 2 1.17
    assert scu.choose_oversampling(m, cbr_range, reps, full_scene_symbols=900)[0] == 2
    # budget 720: s = 3 at 720 / 1152 of its full rate; the views' CBRs spend the budget
    s, scale = scu.choose_oversampling(m, cbr_range, reps, full_scene_symbols=1080)
    assert (s, scale) == (3, pytest.approx(720 / 1152))
    cbr = scu.focus_cbr(m, cbr_range, [0, 1, 2], oversampling=s, scale=scale)
    assert cbr == pytest.approx([720 / 1152 / 24] * 3)
    assert sum(c * 48 * 48 * 3 * r for c, r in zip(cbr, reps)) == pytest.approx(720)
    # however small the scale, a view's rate carries its focus box's side information and
    # one symbol (the codec refuses less)
    tiny = scu.focus_cbr(m, cbr_range, [0, 1, 2], oversampling=s, scale=1e-9)
    assert tiny == pytest.approx([(box_side_symbols(48, 48) + 1) / (3 * 48 * 48)] * 3)
    # a codec with twice the largest CBR: the same budget is the same CBR per position
    # (0.104), so the same s, at half the fraction of the doubled full rate
    wide = scu.choose_oversampling(m, (1 / 48, 1 / 3), reps, full_scene_symbols=1080)
    assert wide == (3, pytest.approx(720 / 2304))
    # budget 160: below 0.09 per position at s = 2 and 3; s = 1 spends all of it
    assert scu.choose_oversampling(m, cbr_range, reps, full_scene_symbols=240) == (1, 160 / 128)
    assert scu.decisions[-1]["full_rate_symbols_by_oversampling"] == {
        str(k): v for k, v in full.items()
    }
    one = SemanticControlUnit(
        Demand.parse("hydrant"), rate_policy=RatePolicy(max_object_oversampling=1)
    )
    assert one.choose_oversampling(m, cbr_range, reps, full_scene_symbols=10**6)[0] == 1
    with pytest.raises(ValueError, match="object_budget_fraction must be in"):
        RatePolicy(object_budget_fraction=1.5)
    with pytest.raises(ValueError, match="min_position_cbr must be in"):
        RatePolicy(min_position_cbr=0.0)


def test_on_demand_copies_only_where_they_fade_independently():
    """The same 8 x 8 object as above in 3 views, each sent twice as a whole view; one copy
    of the three at full rate costs 96 / 384 / 864 symbols at s = 1 / 2 / 3. Budget 540 (2/3
    of 810): with independent fades the copies stay (s = 3 would give 540 / 1728 of its full
    rate, 0.05 CBR per position, so s = 2 at 540 / 768); on a static channel one copy each buys
    s = 3 at 540 / 864. A view measured below ``static_repeat_below_db`` keeps its copies there; a
    budget one copy at s = 3 cannot take (beyond 864) keeps them all."""
    m = np.zeros((3, 16, 16), np.float32)
    m[:, 4:12, 4:12] = 1.0
    reps = np.array([2, 2, 2])
    snr = np.array([0.0, -1.0, 2.0])
    cbr_range = (1 / 48, 1 / 6)
    scu = SemanticControlUnit(Demand.parse("hydrant"))
    fading, static = CopyFading(5.0, 0.0), CopyFading(3.0, 0.9)
    kept = scu.choose_focus_repetitions(m, cbr_range, reps, snr, 810, fading)
    assert kept.tolist() == [2, 2, 2]
    assert scu.choose_oversampling(m, cbr_range, kept, 810) == (2, pytest.approx(540 / 768))
    one = scu.choose_focus_repetitions(m, cbr_range, reps, snr, 810, static)
    assert one.tolist() == [1, 1, 1] and "spent as rate" in scu.decisions[-1]["decision"]
    assert scu.choose_oversampling(m, cbr_range, one, 810) == (3, pytest.approx(540 / 864))
    low = scu.choose_focus_repetitions(m, cbr_range, reps, np.array([0.0, -7.0, 2.0]), 810, static)
    assert low.tolist() == [1, 2, 1]  # 288 * 4 = 1152 at s = 3 takes the 540
    big = scu.choose_focus_repetitions(m, cbr_range, reps, snr, 1350, static)  # 900 > 864
    assert big.tolist() == [2, 2, 2] and "cannot take" in scu.decisions[-1]["decision"]


def test_rate_policy_refuses_a_correlation_outside_minus_one_to_one():
    with pytest.raises(ValueError, match="max_copy_correlation must be in"):
        RatePolicy(max_copy_correlation=2.0)


def test_plan_records_a_static_link_and_keeps_it_through_its_cache():
    """A static link (copies do not fade independently) is what the codec's AWGN simulation
    of its split represents; the plan says which one it is, also when read back."""
    from osnerf.plan import RunPlan

    m = np.zeros((3, 16, 16), np.float32)
    m[:, 4:12, 4:12] = 1.0
    views = [0, 1, 2]
    snr = {v: s for v, s in zip(views, (0.0, -1.0, 2.0), strict=True)}
    scu = SemanticControlUnit(Demand.parse("hydrant"))
    for fading, static in ((CopyFading(5.0, 0.0), False), (CopyFading(3.0, 0.9), True)):
        plan = scu.plan(
            candidates=views,
            on_demand=views,
            link_snr_db=snr,
            measured_snr_db=snr,
            outage=[],
            masks=m,
            cbr_range=(1 / 48, 1 / 6),
            snr_range_db=(-5.0, 20.0),
            height=16,
            width=16,
            copy_fading=fading,
        )
        assert plan.static_link is static
        assert RunPlan.from_dict(plan.to_dict()) == plan
