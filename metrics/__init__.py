"""The metrics engine: per-session metrics, construct-validity statistics, proficiency, learning curves.

The core imports without the web stack. Public API::

    from metrics import compute_session_metrics, construct_validity, REGISTRY
    from metrics.datasets import jigsaws
"""

from metrics.errors import MetricsError
from metrics.session.compute import compute_session_metrics, metrics_of
from metrics.session.registry import REGISTRY, REGISTRY_VERSION, Metric
from metrics.streams import SessionStreams, from_frame, from_recorded
from metrics.study.validity import ConstructValidityResult, construct_validity

__all__ = [
    "REGISTRY",
    "REGISTRY_VERSION",
    "ConstructValidityResult",
    "Metric",
    "MetricsError",
    "SessionStreams",
    "compute_session_metrics",
    "construct_validity",
    "from_frame",
    "from_recorded",
    "metrics_of",
]
