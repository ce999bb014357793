"""The codec contract and the one registry: built-ins, entry-point plugins, bad input, and
focus for codecs that cannot focus."""

import pytest
import torch
from smooth_images import smooth_image

import phy
import semcodec
from semcodec import (
    CODECS,
    CodecPluginError,
    KnowledgeBaseMismatch,
    SemanticCodec,
    TrainableCodec,
    make_codec,
)
from semcodec.contract import BoxMeta


def smooth_images(n: int, h: int, w: int) -> torch.Tensor:
    return torch.cat([smooth_image(i, h, w) for i in range(n)])


def _psnr(x, y) -> float:
    return float(-10 * torch.log10(((x - y) ** 2).mean()))


@pytest.mark.parametrize("name", ["jscc", "deepjscc"])
def test_every_builtin_codec_meets_the_contract(name):
    codec = make_codec(name)
    assert isinstance(codec, SemanticCodec) and isinstance(codec, TrainableCodec)
    lo, hi = codec.cbr_range
    assert 0 < lo < hi and codec.snr_range_db[0] < codec.snr_range_db[1]
    x = smooth_images(2, 24, 40)
    enc = codec.encode(x, 10.0, 1 / 16)
    assert enc.symbols.dtype == torch.complex64 and enc.symbols.shape[0] == 2
    power = enc.symbols.abs().pow(2).mean(dim=1)
    torch.testing.assert_close(power, torch.ones(2), atol=1e-4, rtol=0)
    assert enc.meta.num_symbols == enc.symbols.shape[1]
    assert enc.meta.cbr == pytest.approx(enc.symbols.shape[1] / (3 * 24 * 40))
    y = codec.decode(enc.symbols, enc.meta, 10.0, expected_sha256=codec.sha256)
    assert y.shape == x.shape and 0 <= float(y.min()) and float(y.max()) <= 1
    with pytest.raises(KnowledgeBaseMismatch, match="knowledge base mismatch"):
        codec.decode(enc.symbols, enc.meta, 10.0, expected_sha256="0" * 64)


def test_spec_parsing_and_unknown_names():
    assert semcodec.parse_codec_spec("jscc") == ("jscc", None)
    assert semcodec.parse_codec_spec("jscc:a/b.safetensors") == ("jscc", "a/b.safetensors")
    for bad in ("", ":x", "jscc:"):
        with pytest.raises(ValueError, match="NAME or NAME:CHECKPOINT"):
            semcodec.parse_codec_spec(bad)
    with pytest.raises(KeyError, match=r"unknown codec 'witt'; known: jscc, deepjscc"):
        make_codec("witt")
    assert {"jscc", "deepjscc"} <= set(semcodec.codec_names())


def test_the_jscc_factory_is_load_codec():
    assert make_codec("jscc").sha256 == semcodec.load_codec().sha256
    path = str(semcodec.DEFAULT_CHECKPOINT)
    assert make_codec(f"jscc:{path}").sha256 == semcodec.load_codec(path).sha256


def test_a_checkpoint_of_another_codec_is_refused_naming_both(tmp_path):
    deep = make_codec("deepjscc")
    path = tmp_path / "deep.safetensors"
    sha = deep.save(path, {})
    assert make_codec(f"deepjscc:{path}").sha256 == sha
    with pytest.raises(ValueError) as e:
        make_codec(f"jscc:{path}")
    msg = str(e.value)
    assert "'deepjscc'" in msg and "'jscc'" in msg and sha[:12] in msg and "\n" not in msg
    with pytest.raises(ValueError, match="holds codec 'deepjscc'"):
        semcodec.load_codec(path)
    shipped = make_codec("jscc")
    with pytest.raises(ValueError, match=f"holds codec 'jscc'.*{shipped.sha256[:12]}"):
        make_codec(f"deepjscc:{semcodec.DEFAULT_CHECKPOINT}")


def test_focus_by_box_sends_the_box_at_the_budget():
    codec = make_codec("deepjscc")
    torch.manual_seed(0)
    x = torch.rand(1, 3, 64, 96)
    mask = torch.zeros(1, 1, 64, 96)
    mask[..., 20:30, 40:61] = 1.0
    assert semcodec.contract.mask_box(mask, 64, 96) == (16, 40, 16, 24)
    # the box's side information: 4 coordinates of 5 bits in 4 px units, at 0.5 bit/symbol
    box = semcodec.contract.box_side_symbols(64, 96)
    wide = semcodec.contract.focus_by_box(codec, x, mask, 400, 5.0).meta
    assert box == 40 and wide.side_info_bits() - wide.inner.side_info_bits() == 20
    budget = 16 * 24 * 3 // 16 + box  # CBR 1/16 over the box, and the box's side information
    enc = semcodec.encode_with_focus(codec, x, 5.0, budget / (3 * 64 * 96), mask)
    assert isinstance(enc.meta, BoxMeta) and enc.meta.crop == (16, 40, 16, 24)
    assert enc.meta.num_symbols + box == budget and enc.meta.num_symbols == enc.symbols.shape[1]
    y = semcodec.decode_received(codec, enc.symbols, enc.meta, 40.0, codec.sha256)
    assert y.shape == x.shape
    outside = torch.ones_like(y, dtype=torch.bool)
    outside[..., 16:32, 40:64] = False
    assert torch.all(y[outside] == 0.5)
    # a budget below the smallest rate over the box: the box goes downscaled, within budget
    small = semcodec.contract.focus_by_box(codec, x, mask, box + 10, 5.0)
    assert 4 <= small.meta.num_symbols <= 10 and small.meta.crop == (16, 40, 16, 24)
    y = semcodec.contract.decode_box(codec, small.symbols, small.meta, 5.0)
    assert y.shape == x.shape
    with pytest.raises(ValueError, match="budget_symbols must be >= 1"):
        semcodec.contract.focus_by_box(codec, x, mask, 0, 5.0)
    with pytest.raises(ValueError, match="budget_symbols 3 is below the smallest message"):
        semcodec.contract.focus_by_box(codec, x, mask, box + 3, 5.0)
    with pytest.raises(ValueError, match="does not carry the box's side information"):
        semcodec.contract.focus_by_box(codec, x, mask, box, 5.0)


def test_a_plugin_codec_runs_over_awgn_and_block_rayleigh(plugin):
    codec = make_codec("demo")
    assert type(codec).__module__ == "semcodec_plugin_demo"
    assert not isinstance(codec.module, semcodec.jscc.JSCCModel)
    assert isinstance(codec, SemanticCodec) and not semcodec.is_trainable(codec)
    assert "demo" in semcodec.codec_names()
    x = smooth_images(2, 32, 48)
    for channel in ("awgn", "rayleigh"):
        link = phy.channel_link(channel)
        g = torch.Generator().manual_seed(0)
        lo = semcodec.jscc.transmit_jscc(codec, x, link, 0.0, 1 / 6, generator=g)
        hi = semcodec.jscc.transmit_jscc(codec, x, link, 30.0, 1 / 6, generator=g)
        assert lo.stats["cbr"] == pytest.approx(1 / 6)
        assert lo.stats["side_info_bits"] == 2 * 32
        assert _psnr(hi.images, x) > _psnr(lo.images, x) + 3, channel
        assert _psnr(hi.images, x) > 24, channel  # smooth images: the block means carry most


def test_a_plugin_codec_runs_as_the_eval_codec_link_scheme(plugin):
    codec = make_codec("demo")
    x = smooth_images(1, 32, 32)
    for channel in ("awgn", "rayleigh"):
        ctx = semcodec.links.schemes.EvalContext(channel=channel, codec=codec)
        out = semcodec.LINK_SCHEMES["jscc"](ctx, x, 20.0, 1 / 12, torch.Generator().manual_seed(1))
        assert out.images.shape == x.shape and _psnr(out.images, x) > 20
        with pytest.raises(ValueError, match="cannot refine"):
            semcodec.LINK_SCHEMES["jscc_refined"](ctx, x, 20.0, 1 / 12, None)


def test_a_plugin_without_focus_serves_a_focus_demand_by_its_box(plugin):
    codec = make_codec("demo")
    x = smooth_images(1, 48, 64)
    mask = torch.zeros(1, 1, 48, 64)
    mask[..., 8:20, 16:40] = 1
    g = torch.Generator().manual_seed(0)
    out = semcodec.jscc.transmit_jscc(codec, x, phy.channel_link("awgn"), 30.0, 1 / 48, mask, g)
    box = out.images[..., 8:24, 16:40]
    assert _psnr(box, x[..., 8:24, 16:40]) > 24
    assert torch.all(out.images[..., 30:, :] == 0.5)
    assert out.stats["num_symbols"] <= 48 * 64 * 3 // 48


def test_a_plugin_that_raises_or_returns_no_codec_is_named_in_one_line(plugin):
    with pytest.raises(CodecPluginError) as e:
        make_codec("demo_broken")
    msg = str(e.value)
    assert "demo_broken = semcodec_plugin_demo:broken" in msg and "unreachable" in msg
    assert "\n" not in msg
    with pytest.raises(CodecPluginError, match=r"demo_object .* returned object, not a semantic"):
        make_codec("demo_object")


def test_a_plugin_that_cannot_be_imported_is_named(tmp_path, monkeypatch):
    site = tmp_path / "site"
    info = site / "semcodec_plugin_gone-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: semcodec-plugin-gone\nVersion: 0.1\n"
    )
    (info / "entry_points.txt").write_text("[semcodec.codecs]\ngone = semcodec_plugin_gone:make\n")
    monkeypatch.syspath_prepend(str(site))
    try:
        CODECS.load_entry_points(force=True)  # skipped with a warning line: the rest works
        assert "gone" not in CODECS and "jscc" in CODECS
        with pytest.raises(
            CodecPluginError, match="codec plugin gone = semcodec_plugin_gone:make failed to load"
        ):
            make_codec("gone")
    finally:
        CODECS.broken.pop("gone", None)
        if "gone" in CODECS:
            CODECS.unregister("gone")
