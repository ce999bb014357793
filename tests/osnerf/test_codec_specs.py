"""How commands name, open and record codecs: a bare path to a plugin's checkpoint opens
through the codec its card names, paths are reported as what they are (a folder, a missing
file), a codec without trained weights runs only with ``--allow-untrained`` and says so, and
every command's result records the codec's sha256 and, for a plugin, its distribution.

``tiny`` is a trainable plugin written here against the public contract alone: a 4x4
strided convolution and its transpose, no default weights (its factory without a checkpoint
returns an untrained codec, ``trained = False``), checkpoints as safetensors with the card
the trainer hands it."""

import json
import sys
import textwrap

import numpy as np
import pytest

from osnerf.cli import main
from semcodec import CODECS

TINY = """
import hashlib
import json
from dataclasses import dataclass

import torch
from safetensors import safe_open
from safetensors.torch import load_file, save_file
from torch import nn

ARCHITECTURES = {"tiny_a": 4, "tiny_b": 6}  # complex channels per 4x4 block


@dataclass(frozen=True)
class Meta:
    height: int
    width: int
    num_symbols: int
    cbr: float
    codec_sha256: str

    def side_info_bits(self):
        return 0


class Net(nn.Module):
    def __init__(self, architecture):
        super().__init__()
        self.architecture = architecture
        self.channels = ARCHITECTURES[architecture]
        self.enc = nn.Conv2d(3, 2 * self.channels, 4, stride=4)
        self.dec = nn.ConvTranspose2d(2 * self.channels, 3, 4, stride=4)


def _sha(net):
    h = hashlib.sha256(net.architecture.encode())
    for k, v in sorted(net.state_dict().items()):
        h.update(k.encode() + v.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


class TinyCodec:
    name = "tiny"
    supports_focus = False
    snr_range_db = (-10.0, 30.0)
    architectures = tuple(ARCHITECTURES)

    def __init__(self, net, trained):
        self.module = net
        self.trained = trained
        self.rate_levels = tuple(k / 48 for k in range(1, net.channels + 1))
        self.cbr_range = (self.rate_levels[0], self.rate_levels[-1])
        self.sha256 = _sha(net)

    def untrained(self, architecture=None):
        return TinyCodec(Net(architecture or self.architectures[0]), False)

    def _features(self, x, m):
        f = self.module.enc(x * 2 - 1)  # [batch, 2c, height/4, width/4]
        c = self.module.channels
        return torch.complex(f[:, :m], f[:, c : c + m])

    def _images(self, z, height, width):
        c = self.module.channels
        full = torch.zeros(z.shape[0], c, height // 4, width // 4, dtype=z.dtype)
        full[:, : z.shape[1]] = z
        f = torch.cat([full.real, full.imag], 1)
        return torch.sigmoid(self.module.dec(f))

    def encode(self, images, snr_db, cbr, mask=None, demand_weights=None):
        from semcodec import Encoded

        b, _, h, w = images.shape
        m = max(1, min(self.module.channels, round(cbr * 48)))
        with torch.no_grad():
            z = self._features(images, m).reshape(b, -1)
        z = (z / z.abs().pow(2).mean(1, keepdim=True).sqrt()).to(torch.complex64)
        return Encoded(z, Meta(h, w, z.shape[1], z.shape[1] / (3 * h * w), self.sha256))

    def decode(self, x_hat, meta, snr_db, expected_sha256=None, noise_var=None):
        from semcodec import KnowledgeBaseMismatch

        if expected_sha256 not in (None, self.sha256) or meta.codec_sha256 != self.sha256:
            raise KnowledgeBaseMismatch(f"{expected_sha256} != {self.sha256}")
        b, hf, wf = x_hat.shape[0], meta.height // 4, meta.width // 4
        z = x_hat.reshape(b, -1, hf, wf)
        with torch.no_grad():
            return self._images(z, meta.height, meta.width).clamp(0, 1)

    def forward_train(self, x, snr_db, cbr, channel, generator):
        z = self._features(x, self.module.channels)
        z = z / z.abs().pow(2).mean((1, 2, 3), keepdim=True).sqrt()
        std = (10 ** (-snr_db / 10) / 2).sqrt().reshape(-1, 1, 1, 1)
        noise = torch.randn(z.shape + (2,), generator=generator)
        z = z + std * torch.complex(noise[..., 0], noise[..., 1])
        return self._images(z, x.shape[2], x.shape[3])

    def save(self, path, card):
        self.sha256 = _sha(self.module)
        card = {**card, "architecture": self.module.architecture, "sha256": self.sha256}
        state = {k: v.contiguous() for k, v in self.module.state_dict().items()}
        save_file(state, str(path), metadata={"model_card": json.dumps(card)})
        return self.sha256

    def load_compatible(self, init):
        self.module.load_state_dict(init.module.state_dict())


def make(checkpoint=None):
    if checkpoint is None:
        return TinyCodec(Net("tiny_a"), False)  # no default weights
    with safe_open(str(checkpoint), framework="pt") as f:
        card = json.loads(f.metadata()["model_card"])
    net = Net(card["architecture"])
    net.load_state_dict(load_file(str(checkpoint)))
    return TinyCodec(net, True)
"""


@pytest.fixture
def tiny(tmp_path, monkeypatch):
    """``semcodec-plugin-tiny`` 0.2 with the entry point ``tiny``, on a tmp sys.path."""
    site = tmp_path / "tiny_site"
    info = site / "semcodec_plugin_tiny-0.2.dist-info"
    info.mkdir(parents=True)
    (site / "semcodec_plugin_tiny.py").write_text(textwrap.dedent(TINY))
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: semcodec-plugin-tiny\nVersion: 0.2\n"
    )
    (info / "entry_points.txt").write_text("[semcodec.codecs]\ntiny = semcodec_plugin_tiny:make\n")
    before = dict(CODECS)
    monkeypatch.syspath_prepend(str(site))
    CODECS.load_entry_points(force=True)
    yield "tiny"
    for name in [n for n in CODECS if n not in before]:
        CODECS.unregister(name)
    sys.modules.pop("semcodec_plugin_tiny", None)


def _images(folder, n: int, seed: int):
    from PIL import Image

    folder.mkdir()
    rng = np.random.default_rng(seed)
    for i in range(n):
        a = rng.integers(0, 256, (40, 40, 3), dtype=np.uint8)
        Image.fromarray(a).save(folder / f"{i}.png")
    return folder


def _train_tiny(tmp_path, out, *extra) -> int:
    data, val = _images(tmp_path / "data", 3, 0), _images(tmp_path / "val", 1, 1)
    argv = ["train-codec", "--codec", "tiny", "--data", str(data), "--val", str(val)]
    argv += ["--out", str(out), "--max-steps", "3", "--crop-px", "16", "--batch-size", "2"]
    return main([*argv, "--threads", "1", *extra])


def _eval(images, codec, out, *extra) -> list[str]:
    argv = ["eval-codec", "--images", str(images), "--codec", str(codec), "--schemes", "jscc"]
    return [*argv, "--snr-db", "10", "--no-lpips", "--out", str(out), *extra]


def test_specs_train_codec_defaults_to_the_plugins_architecture_and_logs_as_it_goes(
    tiny, tmp_path, monkeypatch
):
    """Without --model a plugin trains its own first architecture; a 3-step training leaves
    one log.jsonl record per step when records are due every step (a record every 30 s or 50
    steps otherwise, and one at the end)."""
    import semcodec.training.loop as training

    monkeypatch.setattr(training, "LOG_EVERY_S", 0.0)
    out = tmp_path / "run"
    assert _train_tiny(tmp_path, out) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["config"]["model"] == "tiny_a"
    records = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in records][:3] == [1, 2, 3], records
    assert all(np.isfinite(r["loss"]) for r in records[:3])
    assert any(k.startswith("psnr_") for k in records[-1]), records[-1]  # the validation


def test_specs_bare_path_to_a_plugins_checkpoint_evaluates_through_its_card(
    tiny, tmp_path, kodak1, capsys
):
    out = tmp_path / "run"
    assert _train_tiny(tmp_path, out) == 0
    best = out / "best.safetensors"
    from semcodec import read_card

    assert read_card(best)["codec"] == "tiny"  # the trainer's card names the codec
    res = tmp_path / "eval.json"
    assert main(_eval(kodak1, best, res)) == 0, capsys.readouterr().err
    doc = json.loads(res.read_text())
    rec = doc["codec"]
    summary = json.loads((out / "summary.json").read_text())
    assert rec["codec"] == "tiny" and rec["checkpoint"] == str(best) and rec["trained"] is True
    assert rec["sha256"] == summary["codec"]["sha256"] == doc["checkpoint"]["sha256"]
    assert rec["plugin"]["distribution"] == "semcodec-plugin-tiny"
    assert rec["plugin"]["version"] == "0.2"
    assert rec["plugin"]["entry_point"].endswith("tiny = semcodec_plugin_tiny:make")
    assert doc["results"][0]["psnr"] > 0


@pytest.mark.parametrize(
    ("spec", "says"),
    [
        ("{tmp}", "is a folder, not a checkpoint file"),
        ("jscc:{tmp}", "is a folder, not a checkpoint file"),
        ("{tmp}/missing.safetensors", "not found"),
        ("jscc:{tmp}/missing.safetensors", "not found"),
        ("demo:{tmp}/missing.safetensors", "not found"),
        ("demo:{tmp}", "is a folder"),
    ],
)
def test_specs_paths_are_reported_as_what_they_are(plugin, kodak1, tmp_path, spec, says, capsys):
    """A folder is a folder, a missing file is a missing file (never "unknown codec"), and a
    plugin never sees a checkpoint that is not a file (``demo`` would take any)."""
    spec = spec.format(tmp=tmp_path / "ckpts")
    (tmp_path / "ckpts").mkdir()
    res = tmp_path / "x.json"
    assert main(_eval(kodak1, spec, res)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0] and "unknown codec" not in err[0], err
    assert not res.exists()


def test_specs_unknown_name_is_still_an_unknown_codec(kodak1, tmp_path, capsys):
    assert main(_eval(kodak1, "nosuch", tmp_path / "x.json")) == 2
    err = capsys.readouterr().err
    assert "unknown codec 'nosuch'" in err and "jscc" in err


def test_accept_untrained_codec_only_with_allow_untrained(kodak1, tmp_path, capsys):
    """``deepjscc`` without a checkpoint is a freshly initialised network: refused in every
    command that takes --codec, run with --allow-untrained and labelled so."""
    res = tmp_path / "x.json"
    assert main(_eval(kodak1, "deepjscc", res)) == 2
    err = capsys.readouterr().err
    assert "no trained weights" in err and "--allow-untrained" in err and not res.exists()
    ota = ["ota", "--schemes", "jscc", "--codec", "deepjscc", "--images", str(kodak1)]
    ota += ["--size", "48", "--out", str(tmp_path / "ota.json")]
    assert main(ota) == 2 and "--allow-untrained" in capsys.readouterr().err
    run = ["run", "--scene", "tiny", "--resolution", "32", "--views", "4", "--test-views", "2"]
    run += ["--schemes", "jscc,gt", "--codec", "deepjscc", "--out", str(tmp_path / "run")]
    assert main(run) == 2 and "--allow-untrained" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()
    assert main(_eval(kodak1, "deepjscc", res, "--allow-untrained")) == 0
    err = capsys.readouterr().err
    assert "codec deepjscc is untrained" in err
    doc = json.loads(res.read_text())
    assert doc["codec"]["trained"] is False and doc["codec"]["codec"] == "deepjscc"
    assert doc["codec"]["plugin"] is None


def test_provenance_eval_codec_ota_and_sweep_record_the_plugin(plugin, kodak1, tmp_path):
    """The demo plugin (``semcodec-plugin-demo`` 0.1) through eval-codec, ota and a sweep of
    eval-codec: each result carries the codec's sha256 and the plugin's distribution."""
    expect = {"distribution": "semcodec-plugin-demo", "version": "0.1"}

    def check(rec):
        assert rec["sha256"] == "d" * 64 and rec["codec"] == "demo", rec
        assert {k: rec["plugin"][k] for k in expect} == expect, rec
        assert rec["plugin"]["entry_point"] == "semcodec.codecs: demo = semcodec_plugin_demo:make"

    res = tmp_path / "eval.json"
    assert main(_eval(kodak1, "demo", res)) == 0
    check(json.loads(res.read_text())["codec"])
    ota = ["ota", "--tx", "emulated", "--rx", "emulated", "--schemes", "jscc", "--codec", "demo"]
    ota += ["--snr-db", "15", "--images", str(kodak1), "--size", "48", "--max-images", "1"]
    ota += ["--symbols-per-frame", "1024", "--out", str(tmp_path / "ota.json")]
    assert main(ota) == 0
    check(json.loads((tmp_path / "ota.json").read_text())["codec"])
    spec = tmp_path / "spec.yaml"
    spec.write_text(
        "command: eval-codec\n"
        f"fixed: {{images: {kodak1}, codec: demo, schemes: jscc, no_lpips: true}}\n"
        "axes: {snr_db: ['10']}\nseeds: [0]\n"
    )
    out = tmp_path / "sweep.jsonl"
    argv = ["sweep", str(spec), "--out", str(out), "--executor", "serial", "--no-progress"]
    assert main(argv) == 0
    (line,) = [json.loads(x) for x in out.read_text().splitlines()]
    check(line["codec"])


def test_provenance_run_and_train_codec_record_the_codec(plugin, tiny, tmp_path):
    base = ["run", "--scene", "tiny", "--resolution", "32", "--views", "4", "--test-views", "2"]
    base += ["--nerf-steps", "20", "--renderer-steps", "0", "--schemes", "jscc,gt"]
    base += ["--cache-dir", str(tmp_path / "cache"), "--codec", "demo"]
    assert main([*base, "--out", str(tmp_path / "run")]) == 0
    rec = json.loads((tmp_path / "run" / "report.json").read_text())["codec"]
    assert rec["sha256"] == "d" * 64 and rec["plugin"]["distribution"] == "semcodec-plugin-demo"
    assert rec["receiver"] is None and rec["trained"] is True
    out = tmp_path / "train"
    assert _train_tiny(tmp_path, out) == 0
    rec = json.loads((out / "summary.json").read_text())["codec"]
    assert rec["codec"] == "tiny" and rec["checkpoint"] == str(out / "best.safetensors")
    assert rec["plugin"]["distribution"] == "semcodec-plugin-tiny" and len(rec["sha256"]) == 64
    assert rec["plugin"]["version"] == "0.2"
