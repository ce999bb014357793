"""The project's version, declared here only: pyproject reads it, ``osnerf --version`` prints it
and every result file records it."""

__version__ = "0.3.0"
