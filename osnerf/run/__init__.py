"""``osnerf run`` in stages: :func:`run_pipeline` (see :mod:`osnerf.run.pipeline`).

``run_pipeline`` is imported on first use, so the SCU can import the plan types
(:mod:`osnerf.run.plan`) without importing the pipeline that uses the SCU.
"""

from osnerf.run.config import RUN_CHANNELS, RunConfig


def __getattr__(name: str):
    if name == "run_pipeline":
        from osnerf.run.pipeline import run_pipeline

        return run_pipeline
    raise AttributeError(f"module 'osnerf.run' has no attribute {name!r}")


__all__ = ["RUN_CHANNELS", "RunConfig", "run_pipeline"]
