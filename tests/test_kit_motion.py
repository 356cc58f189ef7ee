"""The motion-model kit (issue 23, item 5): every built-in motion model passes every check that applies to it, and
each deliberately wrong model of ``tests/fixtures/wrong_motion.py`` fails the check meant for it with a message
that names the model and the numbers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fixtures import wrong_motion as wrong
from workbench.models import constant_velocity, random_walk_velocity, range_rate_model
from workbench.testing import (MOTION_CHECKS, checks_for, motion_checks_for, parametrize_with_checks, run_checks,
                               run_motion_checks)

GUIDE = (Path(__file__).parents[1] / "docs" / "writing-a-plugin.md").read_text()

#: every built-in motion-model builder, with a few parameter sets (steps from 0.05 s to 7.5 s, noise from none to
#: anisotropic)
BUILTIN = {
    "cv1d": lambda: constant_velocity(1, 1.0, 0.5),
    "cv2d": lambda: constant_velocity(2, 1.0, 0.5),
    "cv2d-fast": lambda: constant_velocity(2, 0.05, 3.0),
    "cv2d-quiet": lambda: constant_velocity(2, 7.5, 0.0),
    "cv3d-aniso": lambda: constant_velocity(3, 0.25, (0.05, 1.0, 4.0)),
    "rwv2d": lambda: random_walk_velocity(2, 1.0, 0.3),
    "rwv3d": lambda: random_walk_velocity(3, 2.5, 2.0),
    "range-rate": lambda: range_rate_model(0.5, 1.5),
    "range-rate-slow": lambda: range_rate_model(4.0, 0.02),
}

#: correct models the built-ins do not cover: nonlinear with a Jacobian, exactly discretised
CORRECT = {
    "ct": lambda: wrong.coordinated_turn(),
    "ct-fast": lambda: wrong.coordinated_turn(0.1, 2.0, 0.1),
    "cwna2d": lambda: wrong.cwna(2, 1.0, 0.3),
    "cwna3d": lambda: wrong.cwna(3, 0.4, 5.0),
}


def _outcomes(model):
    return {o.check: o for o in run_motion_checks(model)}


@pytest.mark.parametrize("label", sorted(BUILTIN))
def test_every_builtin_model_passes_every_applicable_check(label):
    outcomes = _outcomes(BUILTIN[label]())
    assert set(outcomes) == {c.name for c in MOTION_CHECKS}
    failed = {k: o.message for k, o in outcomes.items() if o.status != "passed" and o.status != "skipped"}
    assert not failed, failed
    # the built-ins discretise with an acceleration held over each step (DWNA): only the Q identity is skipped,
    # and the skip says why
    skipped = {k for k, o in outcomes.items() if o.status == "skipped"}
    assert skipped == {"check_noise_composes"}
    assert "exact_discretisation" in outcomes["check_noise_composes"].message


@pytest.mark.parametrize("label", sorted(CORRECT))
def test_correct_nonlinear_and_exact_models_pass(label):
    model = CORRECT[label]()
    outcomes = _outcomes(model)
    failed = {k: o.message for k, o in outcomes.items() if o.status not in ("passed", "skipped")}
    assert not failed, failed
    if label.startswith("ct"):  # nonlinear: its own Jacobian is checked, F is not held to compose
        assert outcomes["check_jacobian"].status == "passed"
        assert outcomes["check_transition_composes"].status == "skipped"
    else:  # exactly discretised: both identities checked
        assert outcomes["check_noise_composes"].status == "passed"
        assert outcomes["check_transition_composes"].status == "passed"


def test_the_turn_model_is_right_independently_of_the_kit():
    """The fixture's turn against a rotation written out item by item, and its Jacobian at omega = 0 against the
    closed-form limit (so the kit's positive control is itself checked)."""
    model = wrong.coordinated_turn(dt=2.0)
    x = np.array([[10.0, -5.0, 3.0, 4.0, 0.3], [0.0, 0.0, 1.0, 0.0, 0.0]])
    out = model.f(x)
    # item 0: the velocity rotated by 0.6 rad; the position moved along the arc (integral of the velocity)
    w, T = 0.3, 2.0
    v = np.array([3.0, 4.0])
    rot = np.array([[np.cos(w * T), -np.sin(w * T)], [np.sin(w * T), np.cos(w * T)]])
    integral = np.array([[np.sin(w * T), -(1 - np.cos(w * T))], [1 - np.cos(w * T), np.sin(w * T)]]) / w
    np.testing.assert_allclose(out[0, 2:4], rot @ v, rtol=1e-13)
    np.testing.assert_allclose(out[0, :2], np.array([10.0, -5.0]) + integral @ v, rtol=1e-13)
    # item 1: omega = 0 is a straight line
    np.testing.assert_allclose(out[1], [2.0, 0.0, 1.0, 0.0, 0.0], atol=1e-15)
    # d x' / d omega at omega = 0 is -T^2 vy / 2 and d y' / d omega is T^2 vx / 2
    J = model.jacobian(x[1])
    assert J[0, 4] == pytest.approx(0.0, abs=1e-15) and J[1, 4] == pytest.approx(T * T / 2.0, rel=1e-12)


WRONG = [
    # (model, the check meant for it, fragments its message must hold)
    (lambda: wrong.coordinated_turn(cls=wrong.TurnJacobianOff), "check_jacobian",
     ["'ct-rate' (TurnJacobianOff)", "jacobian differs from the central differences", "ratio 1.1"]),
    (wrong.not_psd_noise, "check_noise_psd",
     ["'not-psd'", "Q is not positive semi-definite", "eigenvalues", "-0.2303"]),
    (wrong.diagonal_factor, "check_noise_factor",
     ["'diagonal-factor'", "Q_sqrt Q_sqrt^T is not Q", "entry (0, 2) is 0, Q has 0.125"]),
    (wrong.diagonal_factor, "check_noise_samples", ["'diagonal-factor'", "leave the range of Q"]),
    (lambda: wrong.as_class(wrong.MutatingCV), "check_no_mutation",
     ["'mutatingcv' (MutatingCV)", "f wrote into its input", "return a new array"]),
    (lambda: wrong.as_class(wrong.ItemOnlyCV), "check_batched_f",
     ["'itemonlycv' (ItemOnlyCV)", "f raised IndexError on states of shape (3, 5, 4)"]),
    (wrong.stuck_rebuild, "check_transition_composes",
     ["'stuck-rebuild'", "F(dt1 + dt2) = F(dt2) F(dt1) fails", "entry (0, 2) is 1 from for_interval(2.27), 2 composed"]),
    (wrong.dwna_claims_exact, "check_noise_composes",
     ["'dwna-claims-exact' (ExactCV)", "Q(dt1 + dt2) = F(dt2) Q(dt1) F(dt2)^T + Q(dt2) fails"]),
    (wrong.argument_ignoring_growth, "check_time_arguments",
     ["'ignores-time' (ArgumentIgnoringGrowth)", "f(x, t=3.7, dt=1) differs from at(3.7, 1).f(x)"]),
    (wrong.bad_layout, "check_state_layout",
     ["'bad-layout'", "state_names declares 2 names ('x', 'y') for a state of dimension 4", "'metres/s'"]),
]


@pytest.mark.parametrize("make, check, fragments", WRONG, ids=[f"{c}-{i}" for i, (_, c, _) in enumerate(WRONG)])
def test_each_wrong_model_fails_the_check_meant_for_it(make, check, fragments):
    outcome = _outcomes(make())[check]
    assert outcome.status == "failed", outcome
    assert outcome.message.startswith(f"{check}: motion model "), outcome.message
    for fragment in fragments:
        assert fragment in outcome.message, (fragment, outcome.message)


def test_a_mutating_model_fails_only_the_mutation_check():
    """The other checks call ``f`` on copies, so one mistake is reported once, by the check named for it."""
    outcomes = _outcomes(wrong.as_class(wrong.MutatingCV))
    assert [k for k, o in outcomes.items() if o.status == "failed"] == ["check_no_mutation"]


def test_a_turn_without_the_zero_rate_limit_fails_the_jacobian_check():
    """A turn whose formulas divide by omega: NaN at omega = 0, which the kit's zero-rate test state reaches."""

    class NoLimit(wrong.CoordinatedTurn):
        def _terms(self, w):
            T = self.dt
            s, c = np.sin(w * T), np.cos(w * T)
            with np.errstate(divide="ignore", invalid="ignore"):
                return s, c, s / w, (1 - c) / w, (T * c * w - s) / (w * w), (T * s * w - (1 - c)) / (w * w)

    outcome = _outcomes(wrong.coordinated_turn(cls=NoLimit))["check_jacobian"]
    assert outcome.status == "failed", outcome
    assert "jacobian returns a non-finite value at the state [0. 0. 0. 0. 0.]" in outcome.message, outcome.message


def test_the_kit_is_reached_through_the_common_entry_points():
    model = constant_velocity(2, 1.0, 0.5)
    assert [c.name for c in checks_for(model)] == [c.name for c in motion_checks_for(model)]
    assert [o.status for o in run_checks(wrong.not_psd_noise())] == \
        [o.status for o in run_motion_checks(wrong.not_psd_noise())]


@parametrize_with_checks([constant_velocity(2, 1.0, 0.5), wrong.coordinated_turn()])
def test_parametrize_with_checks_takes_motion_models(spec, check):
    check(spec)


def test_every_motion_check_is_documented():
    section = GUIDE[GUIDE.index("**Motion models**"):]
    for check in MOTION_CHECKS:
        assert f"`{check.name}`" in section, check.name
        assert check.description and check.description.strip(), check.name
    assert "`exact_discretisation`" in section
