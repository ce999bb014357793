"""Fixtures of the renderer tests: the analytic sphere dataset (see sphere_scene.py).

pytest's default (prepend) import mode puts ``tests/`` on sys.path, where ``tests/renderer``
(no ``__init__.py``) would shadow the real ``renderer`` as a namespace package; the
repository root goes first instead (``pythonpath = ["."]`` in pytest's ini options would
do the same).
"""

import sys
from pathlib import Path

ROOT = str(Path(__file__).resolve().parents[2])
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)
if "renderer" in sys.modules and getattr(sys.modules["renderer"], "__file__", None) is None:
    del sys.modules["renderer"]  # a namespace package picked up from tests/

import pytest  # noqa: E402
from sphere_scene import write_sphere_dataset  # noqa: E402


@pytest.fixture(scope="session")
def sphere_dataset(tmp_path_factory) -> Path:
    return write_sphere_dataset(tmp_path_factory.mktemp("sphere"))


@pytest.fixture(autouse=True)
def one_torch_thread():
    """One intra-op thread: on a shared, oversubscribed machine two OpenMP threads wait
    on each other and run many times slower. Restored afterwards."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
