"""pytest plugin (entry point ``pytest11``): fixtures for plugin authors.

- ``workbench_host``: a freshly built plugin host (never a shared global).
- ``workbench_filter``: factory ``workbench_filter(name)`` returning an installed filter's spec.
"""

from __future__ import annotations

import pytest


@pytest.fixture
def workbench_host():
    from workbench.plugins import load_host

    return load_host()


@pytest.fixture
def workbench_filter(workbench_host):
    return workbench_host.filter
