"""The plugin test kits: filters (:mod:`.kit`), sensors (:mod:`.sensors`), clutter generators and removers
(:mod:`.clutter`), motion models (:mod:`.motion`), multi-target trackers (:mod:`.trackers`).

From pytest::

    from workbench.testing import parametrize_with_checks
    from my_package.alpha_beta import ALPHA_BETA

    @parametrize_with_checks([ALPHA_BETA])
    def test_conformance(spec, check):
        check(spec)

The kit that fits each spec is chosen by its kind (a filter, sensor, clutter generator or remover spec) and its
checks by its declared capabilities and fields, never by its name.  Test ids read
``alpha-beta-check_batch_consistency`` or ``lband-radar-check_centred_on_h``; checks listed in a filter's
``expected_failures`` are marked ``xfail`` with the declared reason.  Without pytest: ``workbench check-plugin
NAME`` or :func:`run_checks`.
"""

from ..models import MotionModel
from ..specs import ClutterGeneratorSpec, ClutterRemoverSpec, FilterSpec, SensorSpec, TrackerSpec
from . import kit
from ._common import Check, Outcome, Outcomes
from .clutter import GENERATOR_CHECKS, REMOVER_CHECKS, generator_checks_for, remover_checks_for
from .kit import CHECKS, reference_kalman
from .motion import MOTION_CHECKS, motion_checks_for, run_motion_checks
from .sensors import SENSOR_CHECKS, sensor_checks_for
from .trackers import TRACKER_CHECKS, run_tracker_checks, tracker_checks_for

__all__ = ["CHECKS", "SENSOR_CHECKS", "GENERATOR_CHECKS", "REMOVER_CHECKS", "MOTION_CHECKS", "Check", "Outcome",
           "Outcomes", "checks_for", "kit_checks", "run_checks", "reference_kalman", "parametrize_with_checks",
           "motion_checks_for", "run_motion_checks", "TRACKER_CHECKS", "run_tracker_checks"]

#: spec type -> (every check of its kit, the applicable ones)
_KITS = {
    FilterSpec: (CHECKS, kit.checks_for),
    SensorSpec: (SENSOR_CHECKS, sensor_checks_for),
    ClutterGeneratorSpec: (GENERATOR_CHECKS, generator_checks_for),
    ClutterRemoverSpec: (REMOVER_CHECKS, remover_checks_for),
    MotionModel: (MOTION_CHECKS, motion_checks_for),
    TrackerSpec: (TRACKER_CHECKS, tracker_checks_for),
}


def _kit(spec):
    for kind, entry in _KITS.items():
        if isinstance(spec, kind):
            return entry
    raise TypeError(f"no test kit for {type(spec).__name__}; the kits check FilterSpec, SensorSpec, "
                    f"ClutterGeneratorSpec, ClutterRemoverSpec, MotionModel and TrackerSpec")


def kit_checks(spec) -> tuple[Check, ...]:
    """Every check of the kit that fits ``spec`` (applicable or not)."""
    return _kit(spec)[0]


def checks_for(spec) -> list[Check]:
    """The checks of the fitting kit that apply to ``spec`` given its declarations."""
    return _kit(spec)[1](spec)


def run_checks(spec) -> Outcomes:
    """Every check of the fitting kit on ``spec`` without pytest (``passed``, ``failed``, ``skipped`` with the
    reason, ``xfailed`` / ``xpassed`` for a filter's declared expected failures).  The outcomes come as a sequence
    filled as it is read: a caller that iterates (``workbench check-plugin``) sees each as soon as its check
    finishes; ``len()``, indexing and a second iteration see one list.  A component that calls ``sys.exit()`` in a
    check fails that check, named, and the kit goes on."""
    from ._common import run_kit

    if isinstance(spec, FilterSpec):
        return kit.run_checks(spec)
    return run_kit(spec, kit_checks(spec))


def parametrize_with_checks(specs):
    """A ``pytest.mark.parametrize`` over every applicable (component, check) pair, for components of any kind
    (motion models too: ids such as ``cv2d-check_jacobian``)."""
    import pytest

    params = []
    for spec in specs:
        expected = getattr(spec, "expected_failures", {}) or {}
        for check in checks_for(spec):
            marks = ()
            if check.name in expected:
                marks = (pytest.mark.xfail(reason=expected[check.name], strict=True),)
            params.append(pytest.param(spec, check, id=f"{spec.name}-{check.name}", marks=marks))
    return pytest.mark.parametrize("spec, check", params)
