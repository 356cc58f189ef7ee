"""The nearest-neighbour association role (``workbench.tracking.NearestNeighbour`` through ``workbench.tracking.run``)
and its association log (``workbench.metrics.association_log``), on a range / range-rate state.

References: the Kalman filter equations written out in NumPy, the Mahalanobis distance, coasting as the pure
prediction ``F^k x_0``, and the same runs one at a time.
"""

import numpy as np
import pytest

from workbench.metrics import association_log
from workbench.models import linear_measurement, range_rate_model
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.tracking import GATE_99, NearestNeighbour, nearest_candidate, run, strongest_candidate_prior
from workbench.types import CLUTTER, Gaussian, InputError, Scans
from fixtures.candidates import frames

MODEL = linear_measurement(np.eye(2), np.diag([15.0 ** 2, 0.5 ** 2]))
MOTION = range_rate_model(0.5, 1.0)
PRIOR = Gaussian(np.array([[500.0, -4.0]]), np.diag([50.0 ** 2, 5.0 ** 2])[None])


@pytest.fixture(scope="module")
def host():
    return load_host()


def nn_track(spec, prior, scans, gate=None, prior_index=None, reinit_after=None, seed=0):
    return run(spec, scans, MOTION, MODEL, association=NearestNeighbour(gate, prior_index, reinit_after),
               prior=prior, rng=generator(seed))


def test_nn_picks_nearest_by_mahalanobis_and_nis_is_its_d2(host):
    # frame 1: the target near the prediction (498, -4); a candidate closer in range but far in range-rate
    scans = frames([[], [(505.0, -4.2, 0), (490.0, 6.0, CLUTTER), (1500.0, -4.0, CLUTTER)]])
    tr = nn_track(host.filter("kf"), PRIOR, scans)
    assert tr.records["chosen"][0, 1] == 0 and tr.records["updated"][0, 1]
    x_pred = MOTION.F @ PRIOR.mean[0]
    P_pred = MOTION.F @ PRIOR.cov[0] @ MOTION.F.T + MOTION.Q
    S = P_pred + MODEL.R
    nu = np.array([505.0, -4.2]) - x_pred
    assert tr.records["nis"][0, 1] == pytest.approx(nu @ np.linalg.solve(S, nu))
    # the Euclidean nearest in range (490) is farther in Mahalanobis distance
    nu2 = np.array([490.0, 6.0]) - x_pred
    assert nu2 @ np.linalg.solve(S, nu2) > nu @ np.linalg.solve(S, nu)
    np.testing.assert_allclose(tr.records["predicted_z"][0, 1], x_pred)
    np.testing.assert_allclose(tr.records["innovation_cov"][0, 1], S)
    K = P_pred @ np.linalg.inv(S)
    np.testing.assert_allclose(tr.mean[0, 1], x_pred + K @ nu, rtol=1e-10)


def test_no_gate_always_updates_gate_coasts_then_restarts(host):
    far = [(2500.0, 15.0, CLUTTER)]
    scans = frames([[]] + [far] * 5 + [[(2600.0, 15.0, CLUTTER), (480.0, -4.0, 0)]])
    kf = host.filter("kf")
    free = nn_track(kf, PRIOR, scans)
    assert free.records["updated"][0, 1:].all()  # no gate: jumps to the far candidate
    log = association_log(free, scans)
    assert log.wrong[0, 1:6].all() and log.jump[0, 1] and not log.coasted.any()
    gated = nn_track(kf, PRIOR, scans, gate=GATE_99)
    assert not gated.records["updated"][0, 1:6].any() and np.all(gated.records["chosen"][0, 1:6] == -1)
    # coasting: the estimate is the pure prediction x_k = F^k x_0
    np.testing.assert_allclose(gated.mean[0, 5], np.linalg.matrix_power(MOTION.F, 5) @ PRIOR.mean[0])
    assert np.isnan(gated.records["nis"][0, 1:6]).all()
    assert gated.records["updated"][0, 6] and gated.records["chosen"][0, 6] == 1  # the target, inside the gate again
    assert association_log(gated, scans).coasted[0, 1:6].all()
    restart = nn_track(kf, PRIOR, scans, gate=GATE_99, reinit_after=3)
    assert restart.records["restarted"][0, 3] and restart.records["chosen"][0, 3] == 0
    np.testing.assert_allclose(restart.mean[0, 3], [2500.0, 15.0])
    np.testing.assert_allclose(restart.cov[0, 3], PRIOR.cov[0])


def test_association_log_scores_choices_against_the_labels(host):
    scans = frames([[(500.0, -4.0, 0)], [(498.0, -4.0, 0), (1200.0, 3.0, CLUTTER)], [(1190.0, 3.0, CLUTTER)], [],
                    [(494.0, -4.0, 0)]])
    tr = nn_track(host.filter("kf"), PRIOR, scans)
    log = association_log(tr, scans)
    np.testing.assert_array_equal(log.target_present[0], [False, True, False, False, True])
    np.testing.assert_array_equal(log.correct[0], [False, True, False, False, True])
    np.testing.assert_array_equal(log.wrong[0], [False, False, True, False, False])
    np.testing.assert_array_equal(log.coasted[0], [False, False, False, True, False])
    assert log.nn_correct_rate == pytest.approx(1.0)
    # a jump: the chosen range is more than 3 sqrt(S_00) from the predicted one
    S00 = tr.records["innovation_cov"][0, :, 0, 0]
    far = np.abs(np.nan_to_num(tr.records["chosen_z"][0, :, 0]) - tr.records["predicted_z"][0, :, 0]) > 3 * np.sqrt(S00)
    np.testing.assert_array_equal(log.jump[0], far & tr.records["updated"][0])
    assert log.jump[0, 2]
    assert (2, "wrong") in log.events(0) and (3, "coasted") in log.events(0)
    with pytest.raises(InputError, match="origin"):
        association_log(tr, Scans(scans.z, scans.valid, scans.times, snr=scans.snr))  # recorded data: no labels


def test_nn_batch_equals_one_run_at_a_time(host):
    rng = np.random.default_rng(11)
    B, T, M = 5, 8, 4
    z = np.stack([rng.uniform(300, 700, (B, T, M)), rng.uniform(-10, 10, (B, T, M))], -1)
    valid = rng.random((B, T, M)) < 0.7
    scans = Scans(z, valid, 0.5 * np.arange(T), snr=rng.normal(10, 2, (B, T, M)))
    prior, idx = strongest_candidate_prior(scans.scan(0), np.diag([50.0 ** 2, 5.0 ** 2]), [500.0, 0.0])
    kf = host.filter("kf")
    for gate in (None, GATE_99):
        batch = nn_track(kf, prior, scans, gate=gate, prior_index=idx)
        for b in range(B):
            one = nn_track(kf, prior.take(b), Scans(z[b:b + 1], valid[b:b + 1], scans.times, snr=scans.snr[b:b + 1]),
                           gate=gate, prior_index=idx[b:b + 1])
            np.testing.assert_array_equal(batch.records["chosen"][b], one.records["chosen"][0])
            np.testing.assert_allclose(batch.mean[b], one.mean[0], rtol=1e-12)


def test_nearest_candidate_gate_and_empty():
    S = np.broadcast_to(np.diag([100.0, 1.0]), (2, 2, 2))
    z = np.array([[[0.0, 0.0], [25.0, 0.0]], [[0.0, 5.0], [0.0, 0.0]]])
    valid = np.array([[True, True], [True, False]])
    idx, d2 = nearest_candidate(z, valid, np.array([[20.0, 0.0], [0.0, 0.0]]), S, MODEL)
    np.testing.assert_array_equal(idx, [1, 0])
    np.testing.assert_allclose(d2, [0.25, 25.0])
    idx, d2 = nearest_candidate(z, valid, np.array([[20.0, 0.0], [0.0, 0.0]]), S, MODEL, gate=9.21)
    np.testing.assert_array_equal(idx, [1, -1])
    idx, _ = nearest_candidate(np.zeros((2, 0, 2)), np.zeros((2, 0), bool), np.zeros((2, 2)), S, MODEL)
    np.testing.assert_array_equal(idx, [-1, -1])


def test_strongest_candidate_prior_and_its_fallback():
    z = np.array([[[100.0, 1.0], [200.0, 2.0]], [[0.0, 0.0], [0.0, 0.0]]])
    valid = np.array([[True, True], [False, False]])
    snr = np.array([[5.0, 9.0], [np.nan, np.nan]])
    prior, idx = strongest_candidate_prior(Scans(z[:, None], valid[:, None], np.zeros(1), snr=snr[:, None]).scan(0),
                                           np.diag([4.0, 1.0]), [1500.0, 0.0])
    np.testing.assert_array_equal(idx, [1, -1])
    np.testing.assert_allclose(prior.mean, [[200.0, 2.0], [1500.0, 0.0]])
    np.testing.assert_allclose(prior.cov, np.broadcast_to(np.diag([4.0, 1.0]), (2, 2, 2)))


@pytest.mark.parametrize("name", ["ukf", "sir"])
def test_nn_runs_with_another_filter_spec(host, name):
    scans = frames([[(500.0, -4.0, 0)]] + [[(500.0 - 2.0 * k, -4.0, 0), (900.0, 3.0, CLUTTER)] for k in range(1, 6)])
    prior, idx = strongest_candidate_prior(scans.scan(0), PRIOR.cov[0], [1500.0, 0.0])
    tr = nn_track(host.filter(name), prior, scans, gate=GATE_99, prior_index=idx, seed=1)
    assert np.all(tr.records["chosen"][0, 1:] == 0)
    assert abs(tr.mean[0, -1, 0] - 490.0) < 15.0


def test_nn_role_rejects_bad_settings():
    with pytest.raises(InputError, match="gate"):
        NearestNeighbour(gate=0.0)
    with pytest.raises(InputError, match="reinit_after"):
        NearestNeighbour(reinit_after=0)


# -- a filter's own candidate choice (FilterSpec.gate_candidates) and the roles' typed state ------------------------


def _last_valid_row(seen):
    """A filter's ``gate_candidates`` written plainly: every run's last valid row (-1 where none), recording the gate
    it was given."""

    def choose(state, scan, model, gate):
        seen.append(gate)
        out = np.full(scan.valid.shape[0], -1)
        for b in range(scan.valid.shape[0]):
            rows = np.flatnonzero(scan.valid[b])
            if rows.size:
                out[b] = rows[-1]
        return out

    return choose


def test_nn_uses_the_filters_own_choice_where_it_declares_one_and_not_when_asked(host):
    import dataclasses

    # frame 1: the target near the prediction first, a far clutter point last (outside any chi-square gate)
    scans = frames([[], [(505.0, -4.2, 0), (900.0, 3.0, CLUTTER)], []])
    seen = []
    kf = dataclasses.replace(host.filter("kf"), gate_candidates=_last_valid_row(seen))
    own = nn_track(kf, PRIOR, scans, gate=GATE_99)
    assert seen == [GATE_99, GATE_99]  # asked at scans 1 and 2, with the role's gate
    np.testing.assert_array_equal(own.records["chosen"][0], [-1, 1, -1])
    assert own.records["updated"][0].tolist() == [False, True, False]
    # the update is the Kalman update with the chosen candidate; NIS its distance under S = P- + R
    x_pred = MOTION.F @ PRIOR.mean[0]
    P_pred = MOTION.F @ PRIOR.cov[0] @ MOTION.F.T + MOTION.Q
    S = P_pred + MODEL.R
    nu = np.array([900.0, 3.0]) - x_pred
    assert own.records["nis"][0, 1] == pytest.approx(nu @ np.linalg.solve(S, nu), rel=1e-12)
    np.testing.assert_allclose(own.mean[0, 1], x_pred + P_pred @ np.linalg.solve(S, nu), rtol=1e-10)
    np.testing.assert_allclose(own.records["chosen_z"][0, 1], [900.0, 3.0])
    assert np.isnan(own.records["nis"][0, 2])  # an empty scan: coasting, as the nearest neighbour does
    # filter_candidates=False: the nearest under N(x-, P-), the hook never asked
    seen.clear()
    plain = run(kf, scans, MOTION, MODEL, association=NearestNeighbour(GATE_99, filter_candidates=False),
                prior=PRIOR)
    assert seen == [] and plain.records["chosen"][0, 1] == 0


@pytest.mark.parametrize("bad, message", [
    (lambda s, scan, m, g: np.zeros(2, dtype=int), r"one integer row per run, shape \(1,\)"),
    (lambda s, scan, m, g: np.zeros(1), r"one integer row per run"),
    (lambda s, scan, m, g: np.array([2]), r"rows outside -1 \.\. 1: \[2\]"),
    (lambda s, scan, m, g: np.array([1]), "chose an invalid"),
    ("modes", "must be a function"),
])
def test_a_wrong_gate_candidates_is_refused_naming_the_filter(host, bad, message):
    import dataclasses

    scans = frames([[(500.0, -4.0, 0), (600.0, 0.0, CLUTTER)], [(505.0, -4.2, 0)]])  # frame 1: row 1 empty
    kf = dataclasses.replace(host.filter("kf"), name="kf-own", gate_candidates=bad)
    with pytest.raises(InputError, match=f"filter 'kf-own'.*{message}"):
        nn_track(kf, PRIOR, scans, gate=GATE_99)


def test_nn_filter_candidates_must_be_a_bool():
    with pytest.raises(InputError, match="filter_candidates must be True or False"):
        NearestNeighbour(GATE_99, filter_candidates="modes")


def test_a_role_keeps_its_own_typed_state_and_a_dict_is_refused(host):
    from dataclasses import dataclass

    from workbench.tracking import Direct
    from workbench.tracking.single import RoleState

    @dataclass
    class Counted(RoleState):
        predicts: int = 0

    class CountingRole(Direct):
        state_class = Counted

        def begin(self, ctx, prior, first):
            return prior, Counted()

        def predict(self, carry, motion, k):
            carry.role.predicts += 1
            return super().predict(carry, motion, k)

        def finish(self, carry):
            return carry.role.predicts

    scans = frames([[(500.0, -4.0, 0)]] * 4)
    assert run(host.filter("kf"), scans, MOTION, MODEL, association=CountingRole(), prior=PRIOR) == 3

    class DictRole(Direct):
        def begin(self, ctx, prior, first):
            return prior, {"predicts": 0}

    with pytest.raises(InputError, match="DictRole: begin\\(\\) must return its state as a RoleState"):
        run(host.filter("kf"), scans, MOTION, MODEL, association=DictRole(), prior=PRIOR)


def test_a_restart_needs_the_state_to_be_the_measurement(host):
    from workbench.models import constant_velocity

    position = linear_measurement(np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]]), np.eye(2))
    prior = Gaussian(np.array([[0.0, 0.0, 1.0, 1.0]]), np.eye(4)[None])
    scans = frames([[(0.0, 0.0, 0)]] + [[(500.0, 500.0, CLUTTER)]] * 3)
    with pytest.raises(InputError, match="the state \\(4 components\\) must be the measured quantities \\(2\\)"):
        run(host.filter("kf"), scans, constant_velocity(2, 0.5, 0.1), position,
            association=NearestNeighbour(GATE_99, reinit_after=2), prior=prior)
