import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).parent
if str(TESTS) not in sys.path:
    sys.path.insert(0, str(TESTS))


@pytest.fixture
def demo_host():
    """A host with the installed plugins plus the demo fixture plugin (sensor + recipe)."""
    from fixtures import demo_plugin

    from workbench.plugins import load_host

    return load_host(extra_plugins=[("demo", demo_plugin)])
