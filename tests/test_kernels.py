"""The method-C weight kernels against their NumPy reference, on every backend and Taichi arch here, in float64 and
float32."""

import subprocess
import sys

import numpy as np
import pytest
from scipy.special import logsumexp

from workbench_filters.tbd.reference import kernel_inputs, naive_log_weight_sums
from workbench_filters.tbd.reference import tbd_log_weight_sums_reference
from workbench.kernels.runtime import TaichiUnavailable, ensure_taichi, taichi_available_arches
from workbench_filters.tbd.tbd_weights import (EXP_FLOOR, FLOAT32_WEIGHT_RTOL, numba_available, pack_measurements,
                                           pack_points, poly_exp, poly_exp2, resolve_backend, tbd_log_weight_sums)
from workbench_filters.tbd.tbd_weights_numpy import tbd_log_weight_sums_float32

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


def test_poly_exp2_matches_libm_in_each_precision():
    x = -np.concatenate([np.linspace(0.0, 1000.0, 200_001), np.geomspace(1e-300, 1.0, 1000)])
    assert np.max(np.abs(poly_exp2(x) / np.exp2(x) - 1.0)) < 1e-14
    x32 = x[x > -120.0].astype(np.float32)
    got = poly_exp2(x32, "float32")
    assert got.dtype == np.float32
    assert np.max(np.abs(got / np.exp2(x32.astype(float)) - 1.0)) < 4e-7  # a few float32 ulp
    # clamped at the smallest normal of each precision
    assert poly_exp2(np.array([-1e300]))[0] == 2.0**-1022
    assert poly_exp2(np.array([-1e30], dtype=np.float32), "float32")[0] == np.float32(2.0**-126)
    # exp(x) = 2^(x log2 e), for the documentation's natural-log form
    xe = -np.linspace(0.0, 700.0, 10_001)
    assert np.max(np.abs(poly_exp(xe) / np.exp(xe) - 1.0)) < 2e-13
    assert poly_exp(np.array([EXP_FLOOR - 1.0]))[0] == pytest.approx(np.exp(EXP_FLOOR), rel=1e-12)


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
    import workbench_filters.tbd.tbd_weights as kernels

    monkeypatch.setattr(kernels, "SERIAL_PAIRS", serial_pairs)  # the Numba backend has both variants
    rng = np.random.default_rng(11)
    for B, N, M in ((4, 300, 40), (3, 257, 1), (2, 1, 9), (5, 130, 129), (2, 600, 3)):
        args = random_case(rng, B, N, M)
        ref = tbd_log_weight_sums_reference(*args)
        out = tbd_log_weight_sums(*args, backend=backend, arch=arch)
        assert out.shape == (B, N)
        assert np.array_equal(np.isneginf(out), np.isneginf(ref))
        assert np.all(np.isneginf(out[1]))  # the empty gate
        live = np.isfinite(ref)
        np.testing.assert_allclose(out[live], ref[live], rtol=1e-12, atol=1e-9)


def _normalised(log_sums: np.ndarray) -> np.ndarray:
    """Particle weights normalised over each run: ``w_i = exp(l_i) / sum_k exp(l_k)`` per row."""
    return np.exp(log_sums - logsumexp(log_sums, axis=1, keepdims=True))


def _weight_error(log32: np.ndarray, log64: np.ndarray) -> float:
    """The largest ``|w32 - w64| / w64`` over the particles whose normalised weight is at least 1e-12 of the row's
    largest: the float32 tolerance's measure (:data:`FLOAT32_WEIGHT_RTOL`)."""
    w32, w64 = _normalised(log32), _normalised(log64)
    keep = w64 >= 1e-12 * w64.max(axis=1, keepdims=True)
    return float(np.max(np.abs(w32[keep] - w64[keep]) / w64[keep]))


@pytest.mark.parametrize("serial_pairs", [0, 10**12], ids=["threaded", "serial"])
@pytest.mark.parametrize(("backend", "arch"), BACKENDS + [("numpy", "cpu")], ids=IDS + ["numpy"])
def test_float32_kernels_match_the_reference_within_the_stated_tolerance(backend, arch, serial_pairs, monkeypatch):
    import workbench_filters.tbd.tbd_weights as kernels

    monkeypatch.setattr(kernels, "SERIAL_PAIRS", serial_pairs)
    rng = np.random.default_rng(12)
    for B, N, M in ((4, 300, 40), (3, 257, 1), (5, 130, 129)):
        args = random_case(rng, B, N, M)
        ref = tbd_log_weight_sums_reference(*args)
        out = tbd_log_weight_sums(*args, backend=backend, arch=arch, precision="float32")
        assert out.shape == (B, N) and out.dtype == np.float64
        assert np.array_equal(np.isneginf(out), np.isneginf(ref))
        live = np.isfinite(ref)
        # single-precision log-sums: relative error of a few float32 ulp of the log-weights summed
        np.testing.assert_allclose(out[live], ref[live], rtol=2e-6, atol=1e-4)
        rows = np.isfinite(ref).all(axis=1)
        if rows.any():
            assert _weight_error(out[rows], ref[rows]) < FLOAT32_WEIGHT_RTOL
        # the compiled float32 kernels agree with their NumPy float32 twin as closely as with the float64 reference
        twin = tbd_log_weight_sums_float32(*args)
        np.testing.assert_allclose(out[live], twin[live], rtol=2e-6, atol=1e-4)


#: (B, N, M) of the twin tests on the test arch: small and odd shapes, then a million particles (more than a GPU
#: runs at once: the launch's grid) and 16411 measurements (a long loop per particle in each precision).
TWIN_SIZES = {"small": ((4, 300, 40), (3, 257, 1), (2, 1, 9), (5, 130, 129)),
              "large-N": ((2, 1_000_003, 64),), "large-M": ((2, 4099, 16_411),)}


@pytest.mark.parametrize("precision", ["float64", "float32"])
@pytest.mark.parametrize("size", list(TWIN_SIZES))
def test_method_c_weights_on_test_arch_match_the_numpy_twins(test_arch, size, precision):
    # every particle of the kernel's output against the float64 reference (and, in float32, the NumPy float32
    # twin) on ~130 particles of each run, the last ones among them: a particle's log-sum depends on its own state only
    rng = np.random.default_rng(21)
    for B, N, M in TWIN_SIZES[size]:
        points, z, valid, log_pd, sigma_p, s_vr = random_case(rng, B, N, M)
        valid[0, 0] = True  # run 0 sees a detection: every particle of it has a finite log-sum
        out = tbd_log_weight_sums(points, z, valid, log_pd, sigma_p, s_vr, backend="taichi", arch=test_arch,
                                  precision=precision)
        assert out.shape == (B, N) and out.dtype == np.float64
        pick = np.unique(np.r_[np.arange(0, N, max(1, N // 128)), np.arange(max(0, N - 5), N)])  # and the last
        sub = (points[:, pick], z, valid, log_pd, sigma_p, s_vr)
        ref, got = tbd_log_weight_sums_reference(*sub), out[:, pick]
        assert np.array_equal(np.isneginf(got), np.isneginf(ref)) and np.all(np.isneginf(out[1]))  # the empty gate
        assert np.all(np.isfinite(out[0]))
        live = np.isfinite(ref)
        if precision == "float64":
            np.testing.assert_allclose(got[live], ref[live], rtol=1e-12, atol=1e-9)
        else:
            np.testing.assert_allclose(got[live], ref[live], rtol=2e-6, atol=1e-4)
            np.testing.assert_allclose(got[live], tbd_log_weight_sums_float32(*sub)[live], rtol=2e-6, atol=1e-4)
            assert _weight_error(got[:1], ref[:1]) < FLOAT32_WEIGHT_RTOL


def realistic_scene(rng, B=3, N=6_000, clutter=300):
    """Method-C inputs as the filter makes them: particles of the paper-000 prior's spread (500, 500, 300 m; radial
    velocity +-10 m/s) around a target at ~35 km, and in each run the target's detection (SNR ~ 13 dB) among
    ``clutter`` detections spread over a 2.5 km gate (SNR 3..8 dB above the threshold, radial velocity +-300 m/s);
    ``log P_D`` and the position sigmas from the L-band radar's declared detection model, Doppler sigma 15 m/s."""
    from workbench.plugins import load_host

    detection = load_host().sensor("lband-radar").measurement_model().detection
    target = np.array([35e3, 2e3, 2e3, -200.0])
    points = target + rng.normal(size=(B, N, 4)) * [500.0, 500.0, 300.0, 10.0]
    M = clutter + 1
    u = rng.normal(size=(B, M, 3))
    z = np.empty((B, M, 4))
    z[..., :3] = target[:3] + 2500.0 * u / np.linalg.norm(u, axis=-1, keepdims=True) * rng.random((B, M, 1)) ** (1 / 3)
    z[..., 3] = rng.uniform(-300.0, 300.0, (B, M))
    snr = rng.uniform(3.0, 8.0, (B, M))
    snr[:, 0] = 13.0 + rng.normal(size=B)
    rng_m = np.linalg.norm(z[..., :3], axis=-1)
    sigma_p = detection.position_sigma(snr, rng_m)
    z[:, 0, :3] = target[:3] + sigma_p[:, :1] * rng.normal(size=(B, 3))  # the target's own detection
    z[:, 0, 3] = target[3] + 15.0 * rng.normal(size=B)
    return points, z, np.ones((B, M), dtype=bool), detection.log_pd(snr), sigma_p, 15.0


def test_float32_changes_normalised_weights_of_a_realistic_scene_by_less_than_the_tolerance():
    points, z, valid, log_pd, sigma_p, s_vr = realistic_scene(np.random.default_rng(3))
    assert np.all((sigma_p > 5.0) & (sigma_p < 5e3)) and np.all(np.isfinite(log_pd))
    ref = tbd_log_weight_sums(points, z, valid, log_pd, sigma_p, s_vr, backend="numpy")
    w64 = _normalised(ref)
    assert np.all(w64.max(axis=1) < 0.05)  # the weights are spread over many particles (a real update)
    assert np.all(1.0 / np.sum(w64**2, axis=1) > 100)
    backends = ["numba"] if numba_available() else []
    for backend in backends + ["taichi", "numpy"]:
        out = tbd_log_weight_sums(points, z, valid, log_pd, sigma_p, s_vr, backend=backend, arch="cpu",
                                  precision="float32")
        err = _weight_error(out, ref)
        assert err < FLOAT32_WEIGHT_RTOL, (backend, err)
        assert err < FLOAT32_WEIGHT_RTOL / 5, (backend, err)  # with a margin: in fact about 5e-6 here
        # the total variation distance between the two weight vectors is smaller still
        assert 0.5 * np.abs(_normalised(out) - w64).sum(axis=1).max() < 1e-5


def test_precision_is_checked():
    with pytest.raises(ValueError, match="unknown kernel precision"):
        tbd_log_weight_sums(*kernel_inputs(10, 3), backend="numpy", precision="float16")


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
    meas, counts = pack_measurements(z, valid, np.zeros((3, 5)), np.ones((3, 5)), 1.0, "float32")
    assert counts.tolist() == [3, 0, 1]
    assert meas.shape == (3, 6, 3) and meas.dtype == np.float32
    np.testing.assert_allclose(meas[0, :4].T, z[0, [1, 3, 4]], rtol=1e-7)
    np.testing.assert_allclose(meas[2, :4, 0], z[2, 0], rtol=1e-7)
    # c_m = log P_D - 3/2 log(2 pi) - 1/2 log(2 pi) for unit sigmas, a_m = 1/2, both in log2 units
    assert meas[0, 4, 0] == pytest.approx(-2.0 * np.log(2 * np.pi) / np.log(2.0), rel=1e-6)
    assert meas[0, 5, 0] == pytest.approx(0.5 / np.log(2.0), rel=1e-6)


def test_float64_packing_expands_the_log_weight_exactly():
    # log2 w = C_m + T_m . q_i + u_m vr_i - A_m |q_i|^2 + K_i  equals  (c_m - a_m |p_m - p_i|^2 - beta dv^2) / ln 2
    points, z, valid, log_pd, sigma_p, s_vr = random_case(np.random.default_rng(4), B=2, N=7, M=5, p_valid=1.0)
    valid[:] = True
    pts, origin = pack_points(points, s_vr)
    meas, counts = pack_measurements(z, valid, log_pd, sigma_p, s_vr, origin=origin)
    np.testing.assert_allclose(origin, points[:, :, :3].mean(axis=1))
    got = (meas[:, 5, :, None] + np.einsum("bkm,bki->bmi", meas[:, :4], pts[:, :4]) + meas[:, 4, :, None] * pts[:, None, 4]
           + pts[:, None, 5])
    var = sigma_p**2
    c = log_pd - 1.5 * np.log(2 * np.pi * var) - 0.5 * np.log(2 * np.pi * s_vr**2)
    d2 = np.sum((z[:, :, None, :3] - points[:, None, :, :3]) ** 2, axis=-1)
    dv2 = (z[:, :, None, 3] - points[:, None, :, 3]) ** 2
    expect = (c[..., None] - d2 / (2 * var[..., None]) - dv2 / (2 * s_vr**2)) / np.log(2.0)
    np.testing.assert_allclose(got, expect, rtol=1e-12, atol=1e-9)


@pytest.mark.skipif(not numba_available(), reason="the compiled packing is a Numba kernel")
@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_compiled_packing_gives_the_numpy_rows_and_origin_bit_for_bit(precision):
    """The kernels' packing of the particles (compiled, threaded from SERIAL_PACK particles on) against the NumPy
    function it stands in for: every row and the origin identical, for one particle, odd sizes, both compilations,
    far from the origin, and in every layout a filter hands over: C-ordered (the origin summed compiled), Fortran
    order, a slice of wider states, and components outermost (a filter's (n, B, N) states seen as (B, N, n):
    there NumPy's mean sums pairwise, and its own mean is taken)."""
    from workbench_filters.tbd import tbd_weights as tw
    from workbench_filters.tbd import tbd_weights_numba as nb

    rng = np.random.default_rng(17)
    for B, N in [(1, 1), (3, 7), (2, 600), (2, 1001), (5, 4099), (1, tw.SERIAL_PACK + 3)]:
        points = rng.normal(size=(B, N, 4)) * [800.0, 800.0, 500.0, 30.0] + [1e6, -3e5, 2e3, -190.0]
        wider = np.concatenate([points, rng.normal(size=(B, N, 2))], axis=-1)
        layouts = {"C": points, "F": np.asfortranarray(points), "slice": wider[..., :4],
                   "components outermost": np.ascontiguousarray(points.transpose(2, 0, 1)).transpose(1, 2, 0)}
        for name, given in layouts.items():
            expect, origin = pack_points(given, 15.0, precision)
            got, got_origin = tw._pack_points(given, 15.0, precision)
            assert got.dtype == expect.dtype and got.shape == expect.shape
            assert np.array_equal(got, expect) and np.array_equal(got_origin, origin), (B, N, name)
        # both compilations of the rows, whichever the size picked above, and the compiled origin
        expect, origin = pack_points(points, 15.0, precision)
        found = np.empty((B, 3))
        nb.mean_position_compiled(points, found)
        assert np.array_equal(found, origin)
        for fn in ((nb.pack64_serial, nb.pack64_parallel) if precision == "float64"
                   else (nb.pack32_serial, nb.pack32_parallel)):
            out = np.empty_like(expect)
            args = (points, -(0.5 / 15.0**2) * tw.LOG2E) if precision == "float64" else (points,)
            fn(*args, out, origin)
            assert np.array_equal(out, expect), (fn, B, N)
    empty = np.zeros((2, 0, 4))
    got, got_origin = tw._pack_points(empty, 15.0, precision)
    assert got.shape == ((2, 6, 0) if precision == "float64" else (2, 4, 0)) and got_origin.shape == (2, 3)


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
    code = ("import sys, workbench_filters.tbd.tbd_weights, workbench.sensing.radar; "
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

