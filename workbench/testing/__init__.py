"""The plugin test kit.

From pytest::

    from workbench.testing import parametrize_with_checks
    from my_package.alpha_beta import ALPHA_BETA

    @parametrize_with_checks([ALPHA_BETA])
    def test_conformance(spec, check):
        check(spec)

Test ids read ``alpha-beta-check_batch_consistency``; checks listed in the spec's
``expected_failures`` are marked ``xfail`` with the declared reason.  Without pytest:
``workbench check-plugin NAME`` or :func:`run_checks`.
"""

from .kit import CHECKS, Check, Outcome, checks_for, reference_kalman, run_checks

__all__ = ["CHECKS", "Check", "Outcome", "checks_for", "run_checks", "reference_kalman", "parametrize_with_checks"]


def parametrize_with_checks(specs):
    """A ``pytest.mark.parametrize`` over every applicable (filter, check) pair."""
    import pytest

    params = []
    for spec in specs:
        for check in checks_for(spec):
            marks = ()
            if check.name in spec.expected_failures:
                marks = (pytest.mark.xfail(reason=spec.expected_failures[check.name], strict=True),)
            params.append(pytest.param(spec, check, id=f"{spec.name}-{check.name}", marks=marks))
    return pytest.mark.parametrize("spec, check", params)
