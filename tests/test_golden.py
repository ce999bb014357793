"""Reviewed numbers that must not drift (``tests/golden/*.json``), with stated tolerances.

A change that moves one of them on purpose regenerates the file with
``OSNERF_REGEN_GOLDEN=1 pytest tests/test_golden.py`` and says why in its commit.
"""

import json
import os
from pathlib import Path

import numpy as np
import pytest
import torch

GOLDEN = Path(__file__).resolve().parent / "golden"
REGEN = os.environ.get("OSNERF_REGEN_GOLDEN") == "1"


def _check(name: str, got: dict, compare) -> None:
    path = GOLDEN / f"{name}.json"
    if REGEN:
        path.write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
        pytest.skip(f"regenerated {path.name}")
    want = json.loads(path.read_text())
    assert set(got) == set(want), (sorted(got), sorted(want))
    for key in want:
        compare(key, got[key], want[key])


def test_digital_mcs_choice_per_channel_and_snr():
    """The honest digital link's MCS from the average SNR (shipped calibration), exactly:
    a Kodak-sized view at CBR 1/16 on the channels a transmitter plans with."""
    from semcodec.digital.calibration import load_calibration

    cal = load_calibration()
    n_px = 512 * 768
    got = {
        f"{ch}@{snr:g}dB": cal.choose_mcs(ch, snr, n_px * 3 // 16, n_px)[0]
        for ch in ("awgn", "rayleigh", "rayleigh_fast", "tdl")
        for snr in (-5.0, 0.0, 5.0, 10.0, 15.0)
    }

    def same(key, g, w):
        assert g == w, key

    _check("digital_mcs", got, same)


def test_default_codec_on_two_kodak_images(shared_data):
    """The shipped codec's PSNR on kodim01-02 at CBR 1/16 (AWGN and block Rayleigh at 1 and
    10 dB, seed 0): within 0.02 dB (float reductions differ between CPUs by far less)."""
    import phy
    from renderer import psnr
    from semcodec import load_codec
    from semcodec.jscc import transmit_jscc
    from semcodec.links.schemes import load_image_folder

    _, images = load_image_folder(shared_data / "kodak")
    codec = load_codec()
    got = {}
    for ch in ("awgn", "rayleigh"):
        link = phy.channel_link(ch)
        for snr in (1.0, 10.0):
            vals = []
            for k, img in enumerate(images[:2]):
                img = img[:, :, :256, :256]
                g = torch.Generator().manual_seed(k)
                res = transmit_jscc(codec, img, link, snr, 1 / 16, generator=g)
                vals.append(psnr(res.images, img))
            got[f"{ch}@{snr:g}dB"] = float(np.mean(vals))

    def close(key, g, w):
        assert g == pytest.approx(w, abs=0.02), key

    _check("codec_kodak2", got, close)


_MATCHED_SCHEMES = "jscc,digital,digital_genie,ideal,analog"


def _matched_eval(shared_data, tmp_path, channel: str, *flags: str) -> dict:
    """eval-codec on two 128x96 Kodak crops at CBR 1/16, 1 draw, seed 3: each row's numbers
    by ``channel/scheme@snr``."""
    from PIL import Image

    from osnerf.cli import main

    d = tmp_path / "imgs"
    d.mkdir(exist_ok=True)
    for i, name in enumerate(sorted((shared_data / "kodak").iterdir())[:2]):
        Image.open(name).convert("RGB").crop((200, 150, 328, 246)).save(d / f"im{i}.png")
    out = tmp_path / f"{channel}-{len(list(tmp_path.glob('*.json')))}.json"
    argv = ["eval-codec", "--images", str(d), "--channel", channel, "--cbr", "1/16"]
    argv += ["--schemes", _MATCHED_SCHEMES, "--draws", "1", "--seed", "3", "--no-lpips"]
    assert main([*argv, "--out", str(out), *flags]) == 0
    keys = ("psnr_per_draw", "ssim", "failed_codewords", "lost_images", "num_symbols")
    return {
        f"{channel}/{r['scheme']}@{r['snr_db']:g}dB": {k: r[k] for k in keys}
        for r in json.loads(out.read_text())["results"]
    }


def test_exact_knowledge_is_todays_matched_evaluation(shared_data, tmp_path):
    """With the transmitter's belief equal to the channel's SNR (``--plan-snr-db`` at the
    channel SNR, or ``--snr-error-db 0``) every scheme's numbers are those of the matched
    evaluation, to the bit; the matched numbers themselves match the reviewed ones
    (``tests/golden/eval_matched.json``) within 0.02 dB."""
    got = {}
    for ch in ("awgn", "rayleigh"):
        got.update(_matched_eval(shared_data, tmp_path, ch, "--snr-db", "1,10"))

    def close(key, g, w):
        flat = [v for row in g["psnr_per_draw"] for v in row]
        want = [v for row in w["psnr_per_draw"] for v in row]
        assert flat == pytest.approx(want, abs=0.02), key
        assert g["ssim"] == pytest.approx(w["ssim"], abs=1e-3), key
        for k in ("failed_codewords", "lost_images", "num_symbols"):
            assert g[k] == w[k], (key, k)

    _check("eval_matched", got, close)
    no_error = _matched_eval(
        shared_data, tmp_path, "rayleigh", "--snr-db", "1,10", "--snr-error-db", "0"
    )
    assert no_error == {k: v for k, v in got.items() if k.startswith("rayleigh/")}
    planned = _matched_eval(
        shared_data, tmp_path, "rayleigh", "--snr-db", "1", "--plan-snr-db", "1"
    )
    assert planned == {k: v for k, v in got.items() if k.startswith("rayleigh/") and "@1dB" in k}
