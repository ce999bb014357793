"""Shared fixtures of the ``osnerf`` tests: a codec (the shipped default if present, else an
untrained registered architecture), a second codec for knowledge-base refusals, a scene cache,
a small rendering of the tiny scene, and Kodak crops for ``--images``."""

from pathlib import Path

import pytest
import torch

import semcodec


def _checkpoint(path, seed):
    torch.manual_seed(seed)
    model = semcodec.jscc.make_model(sorted(semcodec.jscc.JSCC_ARCHITECTURES)[0])
    semcodec.save_checkpoint(path, model, {"name": f"untrained-{seed}"})
    return str(path)


@pytest.fixture(scope="session")
def env(tmp_path_factory):
    root = tmp_path_factory.mktemp("run")
    default = semcodec.DEFAULT_CHECKPOINT
    codec = str(default) if default.exists() else _checkpoint(root / "a.safetensors", 0)
    other = _checkpoint(root / "b.safetensors", 1)
    return {"root": root, "codec": codec, "other": other, "cache": str(root / "cache")}


@pytest.fixture(scope="session")
def tiny_views(tmp_path_factory):
    """The tiny scene's post, 4 training views of 16 px: enough for its drones' channels."""
    from osnerf.scenes import RenderConfig, build_scene_dataset, load_scene_views

    config = RenderConfig(resolution_px=16, num_train_views=4, num_test_views=1, spp=4, mask_spp=1)
    folder = build_scene_dataset(
        "tiny", ("post",), config, cache_dir=tmp_path_factory.mktemp("scenes"), progress=False
    )
    return load_scene_views(folder)


@pytest.fixture
def one_line(capsys):
    """``one_line()``: the captured stderr so far, asserted to be exactly one line."""

    def read() -> str:
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1, err
        return err

    return read


@pytest.fixture
def kodak_crop(tmp_path, shared_data):
    """``kodak_crop((left, top, right, bottom))``: a folder holding that crop of Kodak's first
    image, for commands that take ``--images``."""

    def make(box) -> Path:
        from PIL import Image

        folder = tmp_path / "img"
        folder.mkdir(exist_ok=True)
        first = sorted((shared_data / "kodak").glob("*.png"))[0]
        Image.open(first).crop(box).save(folder / "k.png")
        return folder

    return make


@pytest.fixture
def kodak1(kodak_crop):
    """Kodak's first image, cropped to 96 x 64 px."""
    return kodak_crop((0, 0, 96, 64))
