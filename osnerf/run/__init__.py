"""``osnerf run`` in stages: :func:`run_pipeline` (see :mod:`osnerf.run.pipeline`)."""

from osnerf.run.config import RUN_CHANNELS, RunConfig
from osnerf.run.pipeline import run_pipeline

__all__ = ["RUN_CHANNELS", "RunConfig", "run_pipeline"]
