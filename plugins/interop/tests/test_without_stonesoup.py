"""Without Stone Soup the interop plugin loads, registers nothing and says nothing; asking for its exports says how
to install it.  Stone Soup is hidden from a fresh interpreter by a package of that name that fails to import."""

import os
import subprocess
import sys
import textwrap

import pytest


@pytest.fixture
def no_stonesoup(tmp_path):
    fake = tmp_path / "stonesoup"
    fake.mkdir()
    (fake / "__init__.py").write_text("raise ImportError(\"No module named 'stonesoup' (hidden by a test)\")\n")
    return dict(os.environ, PYTHONPATH=str(tmp_path) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def test_the_plugin_registers_nothing_and_the_export_says_how_to_install(no_stonesoup):
    code = textwrap.dedent("""
        import numpy as np
        from workbench.plugins import load_host
        from workbench.types import Truth
        from workbench_interop import stonesoup_filters as sf
        from workbench_interop.stonesoup_export import ground_truth_paths

        assert sf.AVAILABLE is False and sf.filters() == []
        assert 'pip install "workbench[stonesoup]"' in sf.REASON, sf.REASON
        host = load_host()
        info = next(p for p in host.plugins if p.name == "stonesoup_interop")
        assert info.status == "ok" and info.provides == () and not info.warnings, info
        assert not [name for name in host.filters if name.startswith("ss-")]
        assert "kf" in host.filters
        try:
            ground_truth_paths(Truth(np.zeros((1, 2, 4)), np.arange(2.0)))
        except ImportError as exc:
            assert "workbench[stonesoup]" in str(exc), exc
        else:
            raise AssertionError("the export worked without Stone Soup")
        print("checked")
    """)
    out = subprocess.run([sys.executable, "-c", code], env=no_stonesoup, capture_output=True, text=True)
    assert out.returncode == 0 and "checked" in out.stdout, out.stderr[-2000:]


def test_the_command_line_stays_quiet(no_stonesoup):
    out = subprocess.run([sys.executable, "-m", "workbench.cli", "plugins"], env=no_stonesoup, capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "ss-ukf" not in out.stdout and "kf" in out.stdout
    assert "stonesoup" not in out.stderr.lower(), out.stderr
