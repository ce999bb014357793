"""osnerf: the semantic control unit, the end-to-end pipeline, sweeps and the CLI."""

from osnerf.provenance import git_commit, result_header, write_json_atomic

# The project's version, declared here only: pyproject reads it, `osnerf --version` prints it
# and every result file records it.
__version__ = "0.2.0"

__all__ = ["__version__", "git_commit", "result_header", "write_json_atomic"]
