"""The registry is whole whatever was imported before reading it, and opening a catalog imports
neither the metric groups nor SciPy's statistics nor the recorder's reader (metrics and recorder
export their names lazily: every spawned worker and CLI run pays for what it imports)."""

import json
import subprocess
import sys

from metrics.session.compute import METRIC_GROUPS
from metrics.session.registry import REGISTRY


def _fresh(code: str) -> dict:
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    return json.loads(done.stdout)


def test_the_registry_read_first_holds_every_group():
    fresh = _fresh(
        "import json\n"
        "from metrics.session.registry import REGISTRY\n"  # nothing else imported before the read
        "print(json.dumps({'names': REGISTRY.names()}))"
    )
    assert fresh["names"] == REGISTRY.names()
    assert len(METRIC_GROUPS) == 6 and len(REGISTRY) > 40  # this process imported the groups itself


def test_opening_the_catalog_module_leaves_the_heavy_parts_unimported():
    loaded = _fresh(
        "import json, sys\n"
        "import sessions.catalog\n"
        "heavy = ['scipy.stats', 'metrics.session.compute', 'recorder.reader', 'recorder.writer']\n"
        "print(json.dumps({name: name in sys.modules for name in heavy}))"
    )
    assert not any(loaded.values()), loaded


def test_the_packages_public_names_resolve_and_unknown_ones_are_attribute_errors():
    import metrics
    import recorder

    assert metrics.REGISTRY is REGISTRY and callable(metrics.compute_session_metrics)
    assert recorder.SCHEMA_VERSION >= 1 and callable(recorder.open_session)
    for package in (metrics, recorder):
        for name in package.__all__:
            assert getattr(package, name) is not None
        try:
            package.no_such_name  # noqa: B018
        except AttributeError as error:
            assert "no_such_name" in str(error)
        else:
            raise AssertionError(f"{package.__name__}.no_such_name resolved")
