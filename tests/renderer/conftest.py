"""Fixtures of the renderer tests: the analytic sphere dataset (see sphere_scene.py)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # sphere_scene, beside this file

import pytest  # noqa: E402
from sphere_scene import write_sphere_dataset  # noqa: E402


@pytest.fixture(scope="session")
def sphere_dataset(tmp_path_factory) -> Path:
    return write_sphere_dataset(tmp_path_factory.mktemp("sphere"))


@pytest.fixture(scope="module")
def sphere_model(sphere_dataset):
    """(the exact sphere written into a grid field, no training needed; its train split)."""
    from sphere_scene import exact_sphere_field

    from renderer import load_dataset

    train_set = load_dataset(sphere_dataset, "train", resolution=None)
    return exact_sphere_field(train_set), train_set


@pytest.fixture(autouse=True)
def one_torch_thread():
    """One intra-op thread: on a shared, oversubscribed machine two OpenMP threads wait
    on each other and run many times slower. Restored afterwards."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
