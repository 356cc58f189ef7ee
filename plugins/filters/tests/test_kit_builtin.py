"""Every built-in filter, discovered through the host exactly as a third-party one, passes the kit."""

from workbench.plugins import load_host
from workbench.testing import parametrize_with_checks

_HOST = load_host()
BUILTIN = [spec for name, spec in sorted(_HOST.filters.items())
           if _HOST.plugin_of("workbench_filters", name).distribution == "workbench"]


@parametrize_with_checks(BUILTIN)
def test_conformance(spec, check):
    check(spec)
