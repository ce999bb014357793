"""The codec contract's optional capabilities, end to end: a codec with a fixed input size
and no differentiable decode (``tests/codec_plugin_fixed.py``) in eval-codec, ota, run and
sweep, with its limits and its symbols against the budget in every result; refinement
through the contract's own terms; the public training channel."""

import json
import re
from pathlib import Path

import pytest
import torch

import semcodec
from osnerf.cli import main

PLUGINS = [Path(__file__).parents[1] / n for n in ("codec_plugin.py", "codec_plugin_fixed.py")]
PRIVATE = ("_snr", "BoxMeta", "masked_transmit", "lmmse_input")


@pytest.fixture
def image_40x24(kodak_crop):
    """One Kodak crop, 40 x 24 px: not a multiple of the plugin's 16 px tiles."""
    return kodak_crop((200, 200, 240, 224))


def test_no_private_semcodec_name_in_either_test_plugin():
    """Both example plugins are written against the public contract alone."""
    for path in PLUGINS:
        text = path.read_text()
        for name in PRIVATE:
            assert name not in text, f"{path.name} uses {name}"
        assert not re.search(r"from semcodec\.\w+ import|import semcodec\.\w+", text), path.name


def test_fixed_codec_in_eval_codec_is_tiled_and_reports_its_budget(
    fixed_plugin, image_40x24, tmp_path, capsys
):
    """40 x 24 px at CBR 1/16 asks 180 symbols; 2 x 3 tiles of 16 px get 30 each, rounded down
    to the codec's 8-symbol steps: 24 per tile, 144 sent, 36 unused, all stated."""
    out = tmp_path / "e.json"
    argv = ["eval-codec", "--images", str(image_40x24), "--codec", "fixed16", "--schemes", "jscc"]
    argv += ["--snr-db", "20", "--cbr", "1/16", "--no-lpips", "--draws", "2"]
    assert main([*argv, "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "codec 'fixed16': no differentiable decode" in err and "fixed input 16x16" in err
    doc = json.loads(out.read_text())
    lim = doc["checkpoint"]["limits"]
    assert lim["input_size"] == [16, 16] and lim["symbol_multiple"] == 8
    assert lim["differentiable_decode"] is False
    row = doc["results"][0]
    assert (row["symbol_budget"], row["num_symbols"], row["symbols_unused"]) == (360, 288, 72)
    assert row["psnr"] > 18.0  # a low-passed picture, tiles put back in place


def test_refinement_asked_for_by_name_is_refused_in_one_line(
    fixed_plugin, image_40x24, tmp_path, one_line
):
    out = tmp_path / "e.json"
    argv = ["eval-codec", "--images", str(image_40x24), "--codec", "fixed16"]
    argv += ["--schemes", "jscc,jscc_refined", "--snr-db", "10", "--no-lpips"]
    assert main([*argv, "--out", str(out)]) == 2
    err = one_line()
    assert "--schemes jscc_refined needs a differentiable decode" in err and "fixed16" in err
    assert not out.exists() and not list(tmp_path.glob("e.json*"))


def test_fixed_codec_over_the_air_between_emulated_hackrfs(fixed_plugin, image_40x24, tmp_path):
    out = tmp_path / "ota.json"
    argv = ["ota", "--tx", "emulated", "--rx", "emulated", "--schemes", "jscc"]
    argv += ["--codec", "fixed16", "--snr-db", "20", "--images", str(image_40x24)]
    argv += ["--size", "24", "--max-images", "1", "--symbols-per-frame", "256"]
    assert main([*argv, "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["codec"]["limits"]["input_size"] == [16, 16]
    assert doc["codec"]["refinement"]["on"] is False
    (row,) = doc["results"]
    assert row["num_symbols"] <= row["symbol_budget"] and row["num_symbols"] % 8 == 0
    s = doc["summary"]["schemes"]["jscc"]
    assert s["symbols_unused"] == s["symbol_budget"] - s["symbols_sent"] >= 0
    assert row["psnr"] > 15.0, row


def test_fixed_codec_in_run_reports_refinement_off_and_the_budget(fixed_plugin, tmp_path, capsys):
    """``osnerf run`` asks for 30 refinement steps by default: a codec that cannot refine
    runs, and its report says refinement was off and why, and the symbols against budget."""
    out = tmp_path / "run"
    argv = ["run", "--scene", "tiny", "--resolution", "32", "--views", "4", "--test-views", "2"]
    argv += ["--nerf-steps", "30", "--renderer-steps", "0", "--schemes", "jscc,gt"]
    argv += ["--cache-dir", str(tmp_path / "cache"), "--codec", "fixed16", "--out", str(out)]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "codec 'fixed16': no differentiable decode" in err
    rep = json.loads((out / "report.json").read_text())
    use = rep["schemes"]["jscc"]["codec_use"]
    assert use["refinement"]["on"] is False and "decode_differentiable" in use["refinement"]["why"]
    assert use["symbols_sent"] == rep["schemes"]["jscc"]["symbols_sent"] > 0
    assert use["symbols_unused"] == use["symbol_budget"] - use["symbols_sent"] >= 0
    assert use["limits"]["input_size"] == [16, 16]
    assert "refinement off" in (out / "report.html").read_text()


def test_fixed_codec_in_a_sweep(fixed_plugin, image_40x24, tmp_path):
    import yaml

    spec = tmp_path / "s.yaml"
    fixed = {"images": str(image_40x24), "codec": "fixed16", "schemes": "jscc", "no_lpips": True}
    spec.write_text(
        yaml.safe_dump({"command": "eval-codec", "fixed": fixed, "axes": {"snr_db": [5, 20]}})
    )
    out = tmp_path / "r.jsonl"
    assert (
        main(["sweep", str(spec), "--out", str(out), "--executor", "serial", "--no-progress"]) == 0
    )
    lines = [json.loads(x) for x in out.read_text().splitlines() if x.strip()]
    assert sorted(ln["point"]["snr_db"] for ln in lines) == [5, 20], lines
    for ln in lines:
        assert ln["metrics"]["checkpoint"]["limits"]["input_size"] == [16, 16]
        assert ln["metrics"]["results"][0]["symbols_unused"] == 36


class _Spy:
    """A codec with a differentiable decode and no focus, 16 x 16 px tiles: its decoders
    record what reaches them (a linear map of 4x4-averaged pixels)."""

    name = "spy"
    sha256 = "5" * 64
    cbr_range = (1 / 64, 1 / 4)
    snr_range_db = (-10.0, 30.0)
    supports_focus = False
    input_size = (16, 16)

    def __init__(self):
        self.seen = []

    def encode(self, images, snr_db, cbr, mask=None, demand_weights=None):
        from dataclasses import dataclass

        @dataclass(frozen=True)
        class Meta:
            height: int
            width: int
            num_symbols: int
            cbr: float
            codec_sha256: str

            def side_info_bits(self):
                return 0

        b, _, h, w = images.shape
        assert (h, w) == (16, 16)
        v = torch.nn.functional.avg_pool2d(images - 0.5, 4).reshape(b, 24, 2)
        sym = torch.view_as_complex(v.contiguous())
        sym = sym / sym.abs().pow(2).mean(1, keepdim=True).sqrt().clamp_min(1e-6)
        return semcodec.Encoded(
            sym.to(torch.complex64), Meta(h, w, 24, 24 / (3 * h * w), self.sha256)
        )

    def _out(self, x_hat):
        v = torch.view_as_real(x_hat).reshape(-1, 3, 4, 4) * 0.1 + 0.5
        return torch.nn.functional.interpolate(v, scale_factor=4).clamp(0, 1)

    def decode(self, x_hat, meta, snr_db, expected_sha256=None, noise_var=None):
        self.seen.append(("decode", type(meta).__name__, None))
        return self._out(x_hat)

    def decode_differentiable(self, x_hat, meta, snr_db, noise_var=None):
        self.seen.append(("differentiable", type(meta).__name__, tuple(snr_db.shape)))
        return self._out(x_hat)


def test_refinement_reaches_the_codec_in_its_own_terms():
    """Focus box and tiles are unwrapped before the codec's decode_differentiable: it gets
    its own meta and the SNR per image, and nothing private is called on it."""
    codec = _Spy()
    g = torch.Generator().manual_seed(0)
    x = torch.rand(1, 3, 40, 40, generator=g)
    mask = torch.zeros(1, 1, 40, 40)
    mask[..., 4:28, 8:30] = 1.0
    enc = semcodec.encode_with_focus(codec, x, 10.0, 1 / 8, mask)
    assert isinstance(enc.meta, semcodec.contract.BoxMeta) and isinstance(
        enc.meta.inner, semcodec.contract.TiledMeta
    )
    import phy

    ref = semcodec.jscc.refine_symbols(
        codec, x, enc, phy.channel_link("awgn"), 10.0, steps=2, generator=torch.Generator()
    )
    assert ref.symbols.shape == enc.symbols.shape and not torch.equal(ref.symbols, enc.symbols)
    kinds = {(k, m, s) for k, m, s in codec.seen}
    assert kinds == {("differentiable", "Meta", (1,))}, kinds
    y = semcodec.decode_received(codec, ref.symbols, ref.meta, 10.0)
    assert y.shape == x.shape and codec.seen[-1][:2] == ("decode", "Meta")


def test_a_registered_codec_with_a_differentiable_decode_refines_in_eval_codec(
    image_40x24, tmp_path
):
    """A codec from outside (registered by name) that declares ``decode_differentiable``:
    jscc_refined runs on it through the command, its tiles' own metas reach its decoder,
    and the refinement moves its symbols."""
    spy = _Spy()
    semcodec.CODECS.register("spy", lambda checkpoint=None: spy)
    try:
        out = tmp_path / "e.json"
        argv = ["eval-codec", "--images", str(image_40x24), "--codec", "spy", "--cbr", "1/8"]
        argv += ["--schemes", "jscc,jscc_refined", "--snr-db", "5", "--no-lpips"]
        assert main([*argv, "--refine-steps", "3", "--out", str(out)]) == 0
    finally:
        semcodec.CODECS.unregister("spy")
    doc = json.loads(out.read_text())
    assert doc["checkpoint"]["refinement"] == {
        "on": True,
        "steps": 3,
        "why": "3 Adam steps per image",
    }
    psnr = {r["scheme"]: r["psnr"] for r in doc["results"]}
    assert psnr["jscc_refined"] != psnr["jscc"], psnr
    assert {m for _, m, _ in spy.seen} == {"Meta"}
    assert ("differentiable", "Meta", (1,)) in spy.seen


def test_an_input_multiple_is_padded_and_cropped_and_tiles_get_their_own_noise():
    """``input_multiple=16``: a 12 x 16 px image reaches the codec edge-padded to 16 x 16 and
    comes back 12 x 16; a fixed-size codec's tiles each get their own slice of a per-symbol
    noise variance."""
    codec = _Spy()
    codec.input_size, codec.input_multiple = None, 16
    x = torch.rand(2, 3, 12, 16, generator=torch.Generator().manual_seed(0))
    assert semcodec.codec_limits(codec).lacks() == [
        "input sides multiples of 16 px: images edge-padded"
    ]
    enc = semcodec.fit_encode(codec, x, 10.0, 1 / 8)
    assert enc.meta.num_symbols == 24 and (enc.meta.height, enc.meta.width) == (12, 16)
    y = semcodec.fit_decode(codec, enc.symbols, enc.meta, 10.0)
    assert y.shape == x.shape
    seen = []
    codec = _Spy()
    codec.decode = lambda x_hat, meta, snr_db, expected_sha256=None, noise_var=None: (
        seen.append(noise_var) or codec._out(x_hat)
    )
    x = torch.rand(1, 3, 16, 32, generator=torch.Generator().manual_seed(1))
    enc = semcodec.fit_encode(codec, x, 10.0, 1 / 8)
    nv = torch.cat([torch.full((1, 24), 0.1), torch.full((1, 24), 0.2)], dim=1)
    assert semcodec.fit_decode(codec, enc.symbols, enc.meta, 10.0, noise_var=nv).shape == x.shape
    assert [float(v.max()) for v in seen] == pytest.approx([0.1, 0.2])


def test_malformed_declarations_are_refused_in_one_line():
    bad = _Spy()
    bad.input_size = (4, 4)
    with pytest.raises(semcodec.CapabilityError, match=r"declares input_size=\(4, 4\)"):
        semcodec.codec_limits(bad)
    bad = _Spy()
    bad.symbol_multiple = 0
    with pytest.raises(
        semcodec.CapabilityError, match="symbol_multiple=0; it must be an integer >= 1"
    ):
        semcodec.codec_limits(bad)


def test_train_channel_returns_what_decode_receives():
    """Unbiased estimates (x_hat conj(x) centred on 1, not shrunk by LMMSE's 1 / (1 + nv))
    with each symbol's noise variance; differentiable in the symbols."""
    g = torch.Generator().manual_seed(0)
    phase = torch.rand(2, 50_000, generator=g) * 6.2832
    x = torch.polar(torch.ones(2, 50_000), phase).requires_grad_(False)
    for ch in ("awgn", "rayleigh_fast"):
        x_hat, nv = semcodec.jscc.train_channel(x, 0.0, ch, g)
        assert x_hat.shape == nv.shape == x.shape and x_hat.dtype == torch.complex64
        gain = (x_hat * x.conj()).real.median().item()  # robust to 1 / |h|^2's tail
        assert abs(gain - 1.0) < 0.02, (ch, gain)
    x_hat, nv = semcodec.jscc.train_channel(x, 0.0, "awgn", g)
    err = (x_hat - x).abs().pow(2).mean().item()
    assert abs(err / nv.mean().item() - 1.0) < 0.02 and abs(nv.mean().item() - 1.0) < 1e-6
    v = x[:, :64].clone().requires_grad_(True)
    out, _ = semcodec.jscc.train_channel(v, torch.tensor([5.0, 10.0]), "rayleigh", g)
    out.abs().pow(2).sum().backward()
    assert v.grad is not None and torch.isfinite(v.grad).all()
    with pytest.raises(KeyError, match="unknown training channel 'nope'"):
        semcodec.jscc.train_channel(x, 0.0, "nope", g)


@pytest.mark.parametrize("name", ["jscc", "deepjscc"])
def test_the_built_in_codecs_declarations(name):
    """Ours refines (it declares a differentiable decode) and takes any size; Deep JSCC,
    registered the way a plugin is, declares no differentiable decode."""
    codec = semcodec.make_codec(name)
    lim = semcodec.codec_limits(codec)
    assert lim.any_size and lim.symbol_multiple == 1
    assert lim.differentiable_decode is (name == "jscc")
    assert semcodec.refinement_status(codec, 5)["on"] is (name == "jscc")
    assert semcodec.refinement_status(codec, 0) == {
        "on": False,
        "steps": 0,
        "why": "refinement steps set to 0",
    }
