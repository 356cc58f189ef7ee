"""The API reference builds from the docstrings with warnings as errors (``mkdocs build --strict``), and it covers
the public API: every name of ``workbench.__all__``, the public modules, the hook specifications, the test kit and
the Stone Soup interoperability package.

Needs the ``docs`` extra (``pip install -e ".[docs]"``); without it the test is skipped and says so.
"""

import importlib.util
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import workbench

ROOT = Path(__file__).parents[1]
NEEDED = ("mkdocs", "mkdocstrings", "mkdocstrings_handlers.python")


def _missing() -> list[str]:
    out = []
    for name in NEEDED:
        try:
            found = importlib.util.find_spec(name) is not None
        except ModuleNotFoundError:
            found = False
        if not found:
            out.append(name)
    return out


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    missing = _missing()
    if missing:
        reason = (f"API reference not built: {', '.join(missing)} not installed (pip install -e \".[docs]\" to build "
                  f"it with warnings as errors)")
        warnings.warn(reason)  # shown in pytest's warnings summary, so the skip is seen
        pytest.skip(reason)
    out = tmp_path_factory.mktemp("api-site")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file",
                           str(ROOT / "mkdocs.yml"), "--site-dir", str(out)], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    log = (done.stdout + done.stderr)[-6000:]
    assert done.returncode == 0, f"mkdocs build --strict failed (warnings are errors):\n{log}"
    return out


def _anchors(site: Path, page: str) -> set[str]:
    html = (site / "api" / page / "index.html").read_text(encoding="utf-8")
    return set(re.findall(r'id="(workbench[A-Za-z0-9_.]*)"', html))


def test_the_reference_builds_strictly_and_documents_every_public_name(site):
    anchors = _anchors(site, "workbench")
    public = [n for n in workbench.__all__ if not n.startswith("__")]
    assert public, "workbench.__all__ names no public API"
    missing = [n for n in public if f"workbench.{n}" not in anchors]
    assert not missing, f"names of workbench.__all__ missing from the reference: {missing}"


@pytest.mark.parametrize("page, module", [
    ("types", "workbench.types"), ("models", "workbench.models"), ("models", "workbench.frames"),
    ("params", "workbench.params"), ("params", "workbench.units"), ("references", "workbench.references"),
    ("specs", "workbench.specs"), ("tracking", "workbench.tracking"),
    ("metrics", "workbench.metrics"), ("metrics", "workbench.metrics.ospa"), ("criteria", "workbench.criteria"),
    ("tracks_io", "workbench.tracks_io"), ("recorded", "workbench.recorded.sonar"),
    ("recorded", "workbench.recorded.pcl"), ("hookspecs", "workbench.hookspecs"), ("testing", "workbench.testing"),
    ("interop", "workbench_interop.stonesoup_filters"), ("interop", "workbench_interop.stonesoup_export"),
])
def test_each_public_module_is_documented_with_its_exports(site, page, module):
    mod = importlib.import_module(module)
    anchors = _anchors(site, page)
    assert module in anchors, f"{module} has no section on api/{page}"
    names = getattr(mod, "__all__", None) or [n for n in vars(mod) if n.startswith("workbench_")]
    documented = [n for n in names if f"{module}.{n}" in anchors]
    # a module's exports are documented, except constants without a docstring of their own
    undocumented = [n for n in names if f"{module}.{n}" not in anchors and callable(getattr(mod, n, None))]
    assert documented and not undocumented, f"{module}: callables missing from api/{page}: {undocumented}"


def test_the_hook_specifications_and_the_kit_entry_point_are_there(site):
    hooks = _anchors(site, "hookspecs")
    for hook in ("workbench_filters", "workbench_sensors", "workbench_clutter_generators",
                 "workbench_clutter_removers", "workbench_report_recipes", "workbench_benchmarks"):
        assert f"workbench.hookspecs.{hook}" in hooks
    assert "workbench.testing.parametrize_with_checks" in _anchors(site, "testing")
