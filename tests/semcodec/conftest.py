"""Fixtures of the semcodec tests (test images: smooth_images.py, beside this file)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # smooth_images, beside this file

import pytest  # noqa: E402
import torch  # noqa: E402

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
