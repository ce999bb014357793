"""The semantic control unit: its decisions (:class:`SemanticControlUnit`) and its rate
policy (:class:`RatePolicy`)."""

from osnerf.scu.policy import RatePolicy, combined_snr_db
from osnerf.scu.unit import KnowledgeBaseError, SemanticControlUnit, padded_aabb

__all__ = [
    "KnowledgeBaseError",
    "RatePolicy",
    "SemanticControlUnit",
    "combined_snr_db",
    "padded_aabb",
]
