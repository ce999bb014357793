"""Knowledge base: checkpoints round-trip; a mismatched hash or a corrupt file is refused."""

import json

import pytest
import torch

from semcodec import DEFAULT_CHECKPOINT, KnowledgeBaseMismatch, load_codec, save_checkpoint
from semcodec.jscc import learned_only, make_model


def test_round_trip_same_outputs_and_hash(tiny_ckpt, tiny_codec, tmp_path):
    x = torch.rand(1, 3, 32, 32, generator=torch.Generator().manual_seed(0))
    enc = tiny_codec.encode(x, 3.0, 1 / 16)
    again = load_codec(tiny_ckpt)
    assert again.sha256 == tiny_codec.sha256 and len(again.sha256) == 64
    torch.testing.assert_close(again.encode(x, 3.0, 1 / 16).symbols, enc.symbols, rtol=0, atol=0)
    # re-saving the same weights keeps the identity
    path = tmp_path / "copy.safetensors"
    assert (
        save_checkpoint(path, again.model, {"name": "copy", "metrics": {"x": 1}})
        == tiny_codec.sha256
    )
    card = load_codec(path).card
    assert card["architecture"]["name"] == "adjscc_s4_w64"
    assert card["cbr_range"] == pytest.approx([1 / 48, 1 / 6])


def test_mismatched_hash_refused(tiny_codec, tmp_path):
    x = torch.rand(1, 3, 32, 32)
    enc = tiny_codec.encode(x, 3.0, 1 / 16)
    torch.manual_seed(1)
    other_path = tmp_path / "other.safetensors"
    save_checkpoint(other_path, make_model("adjscc_s4_w64"))
    other = load_codec(other_path)
    assert other.sha256 != tiny_codec.sha256
    with pytest.raises(KnowledgeBaseMismatch, match="knowledge base mismatch"):
        other.decode(enc.symbols, enc.meta, 3.0)
    with pytest.raises(KnowledgeBaseMismatch):
        tiny_codec.decode(enc.symbols, enc.meta, 3.0, expected_sha256=other.sha256)
    assert issubclass(KnowledgeBaseMismatch, ValueError)


def test_corrupt_checkpoint_one_line_error(tiny_ckpt, tmp_path):
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(b"\x00garbage" * 100)
    with pytest.raises(ValueError, match="corrupt") as e:
        load_codec(bad)
    assert "\n" not in str(e.value)
    # flip bytes inside the weights: the stored hash no longer matches
    data = bytearray(tiny_ckpt.read_bytes())
    data[-100:-90] = bytes(10)
    tampered = tmp_path / "tampered.safetensors"
    tampered.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="corrupt"):
        load_codec(tampered)
    with pytest.raises(FileNotFoundError):
        load_codec(tmp_path / "missing.safetensors")


def test_shipped_default_loads_offline():
    codec = load_codec()
    card = codec.card
    assert card["sha256"] == codec.sha256
    assert codec.cbr_range == pytest.approx((1 / 48, 1 / 3))  # one model up to CBR 1/3
    assert codec.snr_range_db[0] <= -2 and codec.snr_range_db[1] >= 13
    assert "data_sha256" in card["training"]
    side = json.loads((codec.path.parent / "default.card.json").read_text())
    assert side["sha256"] == codec.sha256
    x = torch.rand(1, 3, 32, 48, generator=torch.Generator().manual_seed(0))
    enc = learned_only(codec).encode(x, 10.0, 1 / 3)
    assert enc.meta.num_channels == 16 and enc.symbols.shape[-1] == 16 * 8 * 12


@pytest.mark.parametrize(
    "name, cbr_max", [("mix-v2.2.safetensors", 1 / 6), ("awgn-v1.1.safetensors", 1 / 6)]
)
def test_earlier_shipped_checkpoints_still_load(name, cbr_max):
    codec = load_codec(DEFAULT_CHECKPOINT.parent / name)
    assert codec.cbr_range[1] == pytest.approx(cbr_max) and codec.card["sha256"] == codec.sha256


def test_knowledge_base_versions(tmp_path):
    """v2 models (reliability input) save as format 2 and load; an unknown version is refused
    with a message naming the file and the versions this code reads; v1 stays loadable."""
    import json

    from safetensors.torch import load_file, save_file

    from semcodec import load_checkpoint

    torch.manual_seed(0)
    v2 = make_model("adjscc_s4_w96_rel")
    p = tmp_path / "v2.safetensors"
    save_checkpoint(p, v2, {"name": "v2"})
    model, card = load_checkpoint(p)
    assert card["format_version"] == "2" and model.cfg.decoder_reliability
    assert model.decoder.inp.in_channels == 3 * model.cfg.num_complex_channels
    v1 = tmp_path / "v1.safetensors"
    save_checkpoint(v1, make_model("adjscc_s4_w64"), {"name": "v1"})
    assert load_checkpoint(v1)[1]["format_version"] == "1"
    # a future version
    from safetensors import safe_open

    with safe_open(str(p), framework="pt") as f:
        meta = dict(f.metadata())
    c = json.loads(meta["model_card"])
    c["format_version"] = "9"
    bad = tmp_path / "v9.safetensors"
    save_file(load_file(str(p)), str(bad), metadata={"model_card": json.dumps(c)})
    with pytest.raises(
        ValueError,
        match=r"v9.safetensors is knowledge-base version 9; this osnerf reads versions 1, 2",
    ):
        load_checkpoint(bad)
