import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DATA = Path(os.environ.get("OSNERF_DATA", ROOT.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data (Kodak, BSDS500, nerf_synthetic/lego); skip if absent."""
    if not DATA.is_dir():
        pytest.skip(f"shared data not found at {DATA}")
    return DATA


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """The codec package ``semcodec_plugin_demo`` (``tests/codec_plugin.py``) installed on a
    tmp sys.path with its ``semcodec.codecs`` entry points; removed afterwards."""
    from semcodec import CODECS
    from tests import codec_plugin

    before = dict(CODECS)
    codec_plugin.install(tmp_path, monkeypatch)
    yield
    codec_plugin.uninstall(before)


@pytest.fixture
def fixed_plugin(tmp_path, monkeypatch):
    """The codec package ``semcodec_plugin_fixed`` (``tests/codec_plugin_fixed.py``: 16x16 px
    input, symbols in multiples of 8, no differentiable decode) installed like
    :func:`plugin`; removed afterwards."""
    from semcodec import CODECS
    from tests import codec_plugin_fixed

    before = dict(CODECS)
    codec_plugin_fixed.install(tmp_path, monkeypatch)
    yield
    codec_plugin_fixed.uninstall(before)
