"""The method-C weight kernels against their NumPy reference, on every backend and Taichi arch here."""

import subprocess
import sys

import numpy as np
import pytest
from scipy.special import logsumexp

from workbench.kernels.reference import kernel_inputs, naive_log_weight_sums
from workbench.kernels.reference import tbd_log_weight_sums_reference
from workbench.kernels.runtime import TaichiUnavailable, ensure_taichi, taichi_available_arches
from workbench.kernels.tbd_weights import (EXP_FLOOR, numba_available, pack_measurements, poly_exp, resolve_backend,
                                           tbd_log_weight_sums)

BACKENDS = [("taichi", arch) for arch in taichi_available_arches()] + \
    ([("numba", "cpu")] if numba_available() else [])
IDS = [f"{b}-{a}" for b, a in BACKENDS]


def random_case(rng, B=4, N=300, M=40, p_valid=0.6):
    points = rng.normal(size=(B, N, 4)) * [800.0, 800.0, 500.0, 30.0] + [30e3, 2e3, 2e3, -190.0]
    z = rng.normal(size=(B, M, 4)) * [1500.0, 1500.0, 800.0, 150.0] + [30e3, 2e3, 2e3, -190.0]
    valid = rng.random((B, M)) < p_valid
    valid[1] = False  # an empty gate
    log_pd = np.log(rng.uniform(1e-6, 1.0, (B, M)))
    sigma_p = rng.uniform(20.0, 900.0, (B, M))
    return points, z, valid, log_pd, sigma_p, 15.0


def test_poly_exp_matches_libm_to_double_precision():
    x = -np.concatenate([np.linspace(0.0, 700.0, 200_001), np.geomspace(1e-300, 1.0, 1000)])
    rel = np.abs(poly_exp(x) / np.exp(x) - 1.0)
    assert rel.max() < 5e-14
    assert poly_exp(np.array([-1e300, EXP_FLOOR - 1]))[0] == pytest.approx(np.exp(EXP_FLOOR), rel=1e-13)


def test_reference_equals_direct_logsumexp():
    rng = np.random.default_rng(3)
    points, z, valid, log_pd, sigma_p, s_vr = random_case(rng, B=2, N=50, M=7, p_valid=1.0)
    valid[1] = True
    ref = tbd_log_weight_sums_reference(points, z, valid, log_pd, sigma_p, s_vr, chunk=16)
    # independent algebra: log w = log P_D - |dp|^2/(2 s^2) - 3/2 log(2 pi s^2) - dv^2/(2 s_vr^2) - 1/2 log(2 pi s_vr^2)
    d2 = np.sum((z[:, None, :, :3] - points[:, :, None, :3]) ** 2, axis=-1)
    dv = z[:, None, :, 3] - points[:, :, None, 3]
    var = sigma_p[:, None, :] ** 2
    log_w = log_pd[:, None] - d2 / (2 * var) - 1.5 * np.log(2 * np.pi * var) - dv**2 / (2 * s_vr**2) \
        - 0.5 * np.log(2 * np.pi * s_vr**2)
    np.testing.assert_allclose(ref, logsumexp(log_w, axis=2), rtol=1e-12)
    np.testing.assert_allclose(naive_log_weight_sums(points, z, valid, log_pd, sigma_p, s_vr), ref, rtol=1e-12)


@pytest.mark.parametrize("serial_pairs", [0, 10**12], ids=["threaded", "serial"])
@pytest.mark.parametrize(("backend", "arch"), BACKENDS, ids=IDS)
def test_kernel_matches_reference_on_random_inputs(backend, arch, serial_pairs, monkeypatch):
    import workbench.kernels.tbd_weights as kernels

    monkeypatch.setattr(kernels, "SERIAL_PAIRS", serial_pairs)  # the Numba backend has both variants
    rng = np.random.default_rng(11)
    for B, N, M in ((4, 300, 40), (3, 257, 1), (2, 1, 9), (5, 130, 129)):
        args = random_case(rng, B, N, M)
        ref = tbd_log_weight_sums_reference(*args)
        out = tbd_log_weight_sums(*args, backend=backend, arch=arch)
        assert out.shape == (B, N)
        assert np.array_equal(np.isneginf(out), np.isneginf(ref))
        assert np.all(np.isneginf(out[1]))  # the empty gate
        live = np.isfinite(ref)
        np.testing.assert_allclose(out[live], ref[live], rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize(("backend", "arch"), BACKENDS, ids=IDS)
def test_all_masked_and_zero_width_scans_give_minus_infinity(backend, arch):
    rng = np.random.default_rng(5)
    points, z, valid, log_pd, sigma_p, s_vr = random_case(rng, B=3, N=20, M=6)
    out = tbd_log_weight_sums(points, z, np.zeros_like(valid), log_pd, sigma_p, s_vr, backend=backend, arch=arch)
    assert np.all(np.isneginf(out))
    empty = tbd_log_weight_sums(points, z[:, :0], valid[:, :0], log_pd[:, :0], sigma_p[:, :0], s_vr, backend=backend,
                                arch=arch)
    assert empty.shape == (3, 20) and np.all(np.isneginf(empty))


@pytest.mark.parametrize(("backend", "arch"), BACKENDS, ids=IDS)
def test_weights_stay_finite_when_every_likelihood_underflows(backend, arch):
    rng = np.random.default_rng(8)
    points, z, valid, log_pd, sigma_p, s_vr = random_case(rng, B=2, N=64, M=12, p_valid=1.0)
    valid[:] = True
    points = points + [400e3, 0.0, 0.0, 0.0]  # 400 km from every detection, sigma 10 m: exp(-8e8) = 0
    sigma_p = np.full_like(sigma_p, 10.0)
    out = tbd_log_weight_sums(points, z, valid, log_pd, sigma_p, s_vr, backend=backend, arch=arch)
    ref = tbd_log_weight_sums_reference(points, z, valid, log_pd, sigma_p, s_vr)
    assert np.all(np.isfinite(out)) and np.all(out < -1e8)
    np.testing.assert_allclose(out, ref, rtol=1e-12)
    # and the relative weights survive: the particle nearest to the detections weighs the most
    assert np.argmax(out[0]) == np.argmax(ref[0])


def test_pack_measurements_puts_valid_rows_first_with_counts():
    rng = np.random.default_rng(2)
    z = rng.normal(size=(3, 5, 4))
    valid = np.array([[False, True, False, True, True], [False] * 5, [True, False, False, False, False]])
    meas, counts = pack_measurements(z, valid, np.zeros((3, 5)), np.ones((3, 5)), 1.0)
    assert counts.tolist() == [3, 0, 1]
    assert meas.shape == (3, 6, 3)
    np.testing.assert_array_equal(meas[0, :4].T, z[0, [1, 3, 4]])
    np.testing.assert_array_equal(meas[2, :4, 0], z[2, 0])
    # c_m = log P_D - 3/2 log(2 pi) - 1/2 log(2 pi) for unit sigmas, a_m = 1/2
    assert meas[0, 4, 0] == pytest.approx(-2.0 * np.log(2 * np.pi))
    assert meas[0, 5, 0] == 0.5


def test_backends_resolve_and_reject_unknown_names():
    assert resolve_backend("auto", "cpu") == ("numba" if numba_available() else "taichi")
    assert resolve_backend("auto", "cuda") == "taichi"
    assert resolve_backend("numpy") == "numpy"
    with pytest.raises(ValueError, match="unknown kernel backend"):
        resolve_backend("fortran")
    points, z, valid, log_pd, sigma_p, s_vr = kernel_inputs(10, 3)
    np.testing.assert_allclose(tbd_log_weight_sums(points, z, valid, log_pd, sigma_p, s_vr, backend="numpy"),
                               tbd_log_weight_sums_reference(points, z, valid, log_pd, sigma_p, s_vr))


def test_taichi_runtime_is_lazy_and_checks_its_arch():
    code = ("import sys, workbench.kernels.tbd_weights, workbench.sensing.radar; "
            "import workbench_filters.tbd; print('taichi' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
    assert ensure_taichi("cpu") == "cpu"
    assert ensure_taichi("auto") in taichi_available_arches()  # an already running runtime is kept
    with pytest.raises(ValueError, match="unknown Taichi arch"):
        ensure_taichi("tpu")
    if "cuda" not in taichi_available_arches():
        with pytest.raises(TaichiUnavailable):
            ensure_taichi("cuda")
        assert ensure_taichi("auto") == "cpu"  # the failed request did not tear down the running runtime


def test_the_one_backend_policy():
    from workbench.kernels import backend

    assert backend.resolve("auto", "cpu") == ("numba" if backend.numba_available() else "taichi")
    assert backend.resolve("auto", "cuda") == "taichi" and backend.resolve("auto", "vulkan") == "taichi"
    assert backend.resolve("numpy", "cuda") == "numpy" and backend.resolve("taichi", "cpu") == "taichi"
    with pytest.raises(ValueError, match="CPU only"):
        backend.resolve("numba", "cuda")
    with pytest.raises(ValueError, match="unknown kernel backend"):
        backend.resolve("fortran")
    assert backend.current_arch() == "cpu"
    with backend.using("cuda"):
        assert backend.current_arch() == "cuda" and backend.resolve("auto") == "taichi"
    assert backend.current_arch() == "cpu"  # restored, also after an exception
    with pytest.raises(RuntimeError), backend.using("vulkan"):
        raise RuntimeError("boom")
    assert backend.current_arch() == "cpu"
