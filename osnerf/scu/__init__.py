"""The semantic control unit: its decisions (:class:`SemanticControlUnit`), its rate
policy (:class:`RatePolicy`) and its typed plan (:class:`RunPlan`, one :class:`ViewPlan`
per view), and which views to send (:data:`VIEW_SELECTIONS`)."""

from osnerf.plan import Allocation, RunPlan, ViewLink, ViewPlan, ViewSend
from osnerf.scu.policy import RatePolicy, combined_snr_db
from osnerf.scu.selection import VIEW_SELECTIONS, ViewChoice, select_views
from osnerf.scu.unit import KnowledgeBaseError, SemanticControlUnit, padded_aabb

__all__ = [
    "Allocation",
    "KnowledgeBaseError",
    "RatePolicy",
    "RunPlan",
    "VIEW_SELECTIONS",
    "ViewChoice",
    "SemanticControlUnit",
    "ViewLink",
    "ViewPlan",
    "ViewSend",
    "combined_snr_db",
    "padded_aabb",
    "select_views",
]
