"""The metrics engine: per-session metrics, construct-validity statistics, proficiency, learning curves.

The core imports without the web stack. Public API::

    from metrics import compute_session_metrics, construct_validity, REGISTRY
    from metrics.datasets import jigsaws

The names below load when first used (PEP 562): a process that needs one submodule (the catalog
reads only the registry's version) does not import SciPy's statistics and every metric group.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_WHERE = {
    "MetricsError": "metrics.errors",
    "compute_session_metrics": "metrics.session.compute",
    "metrics_of": "metrics.session.compute",
    "REGISTRY": "metrics.session.registry",
    "REGISTRY_VERSION": "metrics.session.registry",
    "Metric": "metrics.session.registry",
    "SessionStreams": "metrics.streams",
    "from_frame": "metrics.streams",
    "from_recorded": "metrics.streams",
    "ConstructValidityResult": "metrics.study.validity",
    "construct_validity": "metrics.study.validity",
}

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

if TYPE_CHECKING:
    from metrics.errors import MetricsError
    from metrics.session.compute import compute_session_metrics, metrics_of
    from metrics.session.registry import REGISTRY, REGISTRY_VERSION, Metric
    from metrics.streams import SessionStreams, from_frame, from_recorded
    from metrics.study.validity import ConstructValidityResult, construct_validity


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module 'metrics' has no attribute {name!r}")
    return getattr(importlib.import_module(_WHERE[name]), name)
