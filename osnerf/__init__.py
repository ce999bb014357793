"""osnerf: the semantic control unit, the end-to-end pipeline, sweeps and the CLI."""

from osnerf.provenance import git_commit, result_header, write_json_atomic
from osnerf.version import __version__

__all__ = ["__version__", "git_commit", "result_header", "write_json_atomic"]
