"""Fixtures of the semcodec tests (test images: smooth_images.py, beside this file)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # smooth_images, beside this file

import json  # noqa: E402

import pytest  # noqa: E402
import torch  # noqa: E402
from smooth_images import write_images  # noqa: E402

from semcodec import load_codec, save_checkpoint
from semcodec.jscc import make_model


@pytest.fixture(scope="session", autouse=True)
def _threads():
    torch.set_num_threads(1)


@pytest.fixture(scope="session")
def tiny_ckpt(tmp_path_factory):
    """A randomly initialised small codec saved as a checkpoint (fast, deterministic)."""
    torch.manual_seed(0)
    model = make_model("adjscc_s4_w64")
    path = tmp_path_factory.mktemp("ckpt") / "tiny.safetensors"
    save_checkpoint(path, model, {"name": "tiny-test"})
    return path


@pytest.fixture(scope="session")
def tiny_codec(tiny_ckpt):
    return load_codec(tiny_ckpt)


@pytest.fixture
def tiny_campaign(tmp_path):
    """A campaign folder with one from-scratch line of the small architecture, tiny crops,
    and its data (3 training images, 2 held-out ones)."""
    doc = json.loads(
        (Path(__file__).resolve().parents[2] / "campaign" / "campaign.json").read_text()
    )
    doc["validation"].update(count=2, side_px=32, channels="awgn")
    del doc["validation"]["images_sha256"]  # its own held-out set, pinned by its first stretch
    doc["lines"] = {
        "tiny": {
            "model": "adjscc_s4_w64",
            "train": {"channel": "awgn", "batch_size": 2, "crop_px": 32, "warmup_steps": 2},
            "lrs": [1e-3, 5e-4],
            "seed": 0,
            "best": None,
        }
    }
    doc["default_line"] = "tiny"
    camp = tmp_path / "camp"
    camp.mkdir()
    (camp / "campaign.json").write_text(json.dumps(doc))
    train = write_images(tmp_path / "train", 3, 48, 0)
    val = write_images(tmp_path / "val", 2, 40, 100)
    argv = ["continue", "--campaign", str(camp), "--steps", "6", "--device", "cpu"]
    argv += ["--data", str(train), "--val", str(val), "--work", str(tmp_path / "work")]
    return camp, argv
