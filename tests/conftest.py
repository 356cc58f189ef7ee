import os
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).parent
if str(TESTS) not in sys.path:
    sys.path.insert(0, str(TESTS))


@pytest.fixture(scope="session", autouse=True)
def _reports_save_png_only():
    """The suite's reports save each figure as PNG only (``WORKBENCH_REPORT_FORMATS=png``, unless the environment
    already names the formats): drawing every figure a second time for its SVG doubled the reports' cost in the
    tests, and the SVG output has tests of its own (tests/test_report.py, which ask for it by name)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("WORKBENCH_REPORT_FORMATS", os.environ.get("WORKBENCH_REPORT_FORMATS", "png"))
        yield


@pytest.fixture(scope="session", autouse=True)
def _reports_run_in_process():
    """The suite's reports run their tasks in the test's own process (``WORKBENCH_JOBS=1``, unless the environment
    already sets it): the test files already run side by side on the cores (pytest-xdist), and a pool of worker
    processes per report would start a fresh interpreter per core for each report.  The worker pool has tests of its
    own (tests/test_report_jobs.py, which ask for it by name with ``--jobs`` or an executor)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("WORKBENCH_JOBS", os.environ.get("WORKBENCH_JOBS", "1"))
        yield


@pytest.fixture
def demo_host():
    """A host with the installed plugins plus the demo fixture plugin (sensor + recipe)."""
    from fixtures import demo_plugin

    from workbench.plugins import load_host

    return load_host(extra_plugins=[("demo", demo_plugin)])


@pytest.fixture
def test_arch():
    """The Taichi arch of the ``on_test_arch`` kernel tests, the ones ``scripts/gpu-check.sh`` runs:
    ``WORKBENCH_TEST_ARCH`` (``cuda`` on a GPU, ``cpu`` standing in for it), and the test fails where Taichi cannot
    start on the arch it names; unset, ``cuda`` where Taichi finds one, else the test skips."""
    from workbench.kernels.runtime import taichi_available_arches

    arch = os.environ.get("WORKBENCH_TEST_ARCH")
    available = taichi_available_arches()
    if arch is None:
        if "cuda" not in available:
            pytest.skip("no CUDA device for Taichi here (WORKBENCH_TEST_ARCH=cpu runs these on the CPU)")
        return "cuda"
    if arch not in available:
        pytest.fail(f"WORKBENCH_TEST_ARCH={arch}: Taichi cannot start on it here (it finds {', '.join(available)})")
    return arch
