"""``osnerf run`` in stages: :func:`run_pipeline` (see :mod:`osnerf.run.pipeline`).

The plan types live in :mod:`osnerf.plan` (the SCU decides them) and the scheme
types in :mod:`osnerf.scheme_types`, so nothing below this package imports it back.
"""

from osnerf.run.config import RUN_CHANNELS, RunConfig
from osnerf.run.pipeline import run_pipeline

__all__ = ["RUN_CHANNELS", "RunConfig", "run_pipeline"]
