"""Every built-in filter, discovered through the host exactly as a third-party one, passes the kit."""

from workbench.plugins import load_host
from workbench.testing import checks_for, parametrize_with_checks

_HOST = load_host()
# the built-in filter plugins (the Stone Soup adapters, also of this distribution, have their own kit test)
BUILTIN = [spec for name, spec in sorted(_HOST.filters.items())
           if _HOST.plugin_of("workbench_filters", name).module.startswith("workbench_filters.")]

#: The checks for the bugs plugin authors really make, with what each needs declared.
EVERY_FILTER = {"check_partially_measured_batch", "check_previous_state_unchanged", "check_nan_not_hidden"}
RANGE_BEARING = {"check_bearing_wrap", "check_range_bearing_accuracy"}


@parametrize_with_checks(BUILTIN)
def test_conformance(spec, check):
    check(spec)


def test_the_checks_for_real_bugs_run_over_every_builtin():
    assert len(BUILTIN) >= 12
    takes_range_bearing = 0
    for spec in BUILTIN:
        names = {c.name for c in checks_for(spec)}
        assert EVERY_FILTER <= names, spec.name
        accepts = not {"linear_only", "position_doppler_3d"} & spec.capabilities
        assert (RANGE_BEARING <= names) == accepts and (not RANGE_BEARING & names) == (not accepts), spec.name
        takes_range_bearing += accepts
    assert takes_range_bearing >= 8
