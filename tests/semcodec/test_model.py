"""Registry, rate masks and shapes."""

import pytest
import torch

from semcodec.jscc import (
    JSCC_ARCHITECTURES,
    JSCCConfig,
    features_to_symbols,
    learned_only,
    make_model,
    symbols_to_features,
)
from semcodec.jscc.model import side_info


@pytest.mark.parametrize("name", sorted(JSCC_ARCHITECTURES))
def test_registry_builds_every_name(name):
    model = make_model(name)
    cfg = model.cfg
    assert cfg.name == name
    x = torch.rand(2, 3, 16, 24)
    side = side_info(torch.tensor([0.0, 10.0]), 3, cfg.num_complex_channels, 2)
    with torch.no_grad():
        feat = model.encoder(x, side)
        rel = torch.ones(2, cfg.num_complex_channels, 4, 6)
        y = model.decoder(feat, side, rel)
    assert feat.shape == (2, 2 * cfg.num_complex_channels, 4, 6)
    assert y.shape == x.shape and float(y.min()) >= 0 and float(y.max()) <= 1


def test_unknown_model_lists_known():
    with pytest.raises(KeyError, match="adjscc_s4_w96"):
        make_model("nope")


def test_config_validation_names_field():
    with pytest.raises(ValueError, match="width"):
        JSCCConfig(width=2)
    with pytest.raises(ValueError, match="snr_min_db"):
        JSCCConfig(snr_min_db=10.0, snr_max_db=0.0)


def test_cbr_range_is_1_48_to_1_6():
    cfg = JSCCConfig()
    assert cfg.cbr_range == pytest.approx((1 / 48, 1 / 6))


@pytest.mark.parametrize("m", [1, 3, 8])
def test_symbols_round_trip_and_rate_mask_keeps_m(m):
    g = torch.Generator().manual_seed(m)
    feat = torch.randn(2, 16, 3, 5, generator=g)
    sym = features_to_symbols(feat, m)
    assert sym.shape == (2, m * 15) and sym.dtype == torch.complex64
    back = symbols_to_features(sym, m, 8, 3, 5)
    torch.testing.assert_close(back[:, : 2 * m], feat[:, : 2 * m])
    assert torch.count_nonzero(back[:, 2 * m :]) == 0
    # channel k = planes (2k, 2k+1) as (real, imag)
    assert sym[0, 0] == torch.complex(feat[0, 0, 0, 0], feat[0, 1, 0, 0])


@pytest.mark.parametrize("k", range(1, 9))
def test_codec_sends_exactly_k_channels_per_position(tiny_codec, k):
    x = torch.rand(1, 3, 32, 40)
    enc = learned_only(tiny_codec).encode(x, 0.0, k / 48)  # no analog layer
    assert enc.meta.num_channels == k
    assert enc.symbols.shape == (1, k * 8 * 10)
    assert enc.meta.cbr == pytest.approx(k / 48)


def test_cbr_outside_range_is_refused(tiny_codec):
    x = torch.rand(1, 3, 32, 32)
    for bad in (1 / 100, 1 / 4, float("nan")):
        with pytest.raises(ValueError, match="cbr"):
            tiny_codec.encode(x, 0.0, bad)


def test_bad_images_are_refused(tiny_codec):
    with pytest.raises(ValueError, match="RGB"):
        tiny_codec.encode(torch.rand(1, 1, 32, 32), 0.0, 1 / 16)
    with pytest.raises(ValueError, match="at least"):
        tiny_codec.encode(torch.rand(1, 3, 4, 32), 0.0, 1 / 16)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        tiny_codec.encode(torch.rand(1, 3, 32, 32) * 255, 0.0, 1 / 16)


def test_odd_sizes_round_trip(tiny_codec):
    x = torch.rand(1, 3, 30, 37)
    enc = tiny_codec.encode(x, 5.0, 1 / 16)
    y = tiny_codec.decode(enc.symbols, enc.meta, 5.0)
    assert y.shape == x.shape
    assert enc.meta.num_symbols == 3 * 8 * 10  # ceil(30/4) x ceil(37/4) positions


@pytest.mark.parametrize("m", [1, 3, 8])
def test_widened_model_decodes_as_its_init_at_the_init_rates(m):
    """A 16-channel model started from an 8-channel one reconstructs bit for bit the same
    at every rate the 8-channel one serves (noise-free link: the AF rate input is rescaled,
    the extra encoder outputs are dropped, the extra decoder planes are zero)."""
    from semcodec.jscc.model import reliability_to_features
    from semcodec.training.loop import load_compatible

    torch.manual_seed(0)
    old = make_model("adjscc_s4_w96_rel").eval()
    new = make_model("adjscc_s4_w96_rel_c16").eval()
    load_compatible(new, old)
    x = torch.rand(2, 3, 16, 16)

    def through(model):
        c = model.cfg.num_complex_channels
        side = side_info(torch.tensor([1.0, 10.0]), m, c, 2)
        feat = model.encoder(x, side)
        sym = features_to_symbols(feat, m)
        z = symbols_to_features(sym, m, c, 4, 4)
        rel = reliability_to_features(torch.full(sym.shape, 0.9), m, c, 4, 4)
        return model.decoder(z, side, rel)

    with torch.no_grad():
        torch.testing.assert_close(through(new), through(old), atol=1e-6, rtol=0)
        assert new.cfg.cbr_range[1] == pytest.approx(1 / 3)


def test_narrowing_init_is_refused():
    from semcodec.training.loop import load_compatible

    with pytest.raises(ValueError, match="does not fit"):
        load_compatible(make_model("adjscc_s4_w96_rel"), make_model("adjscc_s4_w96_rel_c16"))
