"""Where shared data lives: ``../shared/data`` beside the checkout, or ``$OSNERF_DATA``."""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent


def shared_data_dir() -> Path:
    """The shared data folder (Kodak, BSDS500, nerf_synthetic); never downloaded."""
    env = os.environ.get("OSNERF_DATA")
    return Path(env) if env else (REPO_ROOT.parent / "shared" / "data")
