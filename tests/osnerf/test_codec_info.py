"""`osnerf codec-info`: parameters and multiply-accumulates counted by torch, for a plugin."""

import json

import pytest
from PIL import Image

from osnerf.cli import main


@pytest.fixture
def image_64(shared_data, tmp_path):
    path = tmp_path / "img" / "crop.png"
    path.parent.mkdir()
    kodak = sorted((shared_data / "kodak").iterdir())[0]
    Image.open(kodak).convert("RGB").crop((0, 0, 64, 64)).save(path)
    return path


def test_the_plugin_codec_costs_its_matrix_products(plugin, image_64, tmp_path, capsys):
    """The demo plugin projects each 4x4x3 block on 2m basis vectors (m = 48 CBR complex
    symbols per block): 2m x 48 MACs per 16 pixels each way, no parameters, one buffer."""
    out = tmp_path / "info.json"
    argv = ["codec-info", "--codec", "demo", "--image", str(image_64), "--cbr", "1/16"]
    assert main([*argv, "--repeats", "1", "--no-digital", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert json.loads(capsys.readouterr().out) == doc
    c = doc["complexity"]
    m = 3  # round(48 / 16)
    assert c["encode_macs_per_pixel"] == pytest.approx(2 * m * 48 / 16)
    assert c["decode_macs_per_pixel"] == pytest.approx(2 * m * 48 / 16)
    assert c["parameters"] == 0 and c["buffers"] == 16 * 48  # the basis, 2 x 8 complex
    assert c["encode_seconds"] > 0 and c["decode_seconds"] > 0
    assert doc["codec"]["name"] == "demo" and "digital" not in doc
