"""Signal-level passive coherent location (PCL): DTV-like signals, ECA, the cross-ambiguity function, CA-CFAR.

Pipeline of one frame (one coherent processing interval, CPI)::

    reference r[n]     band-limited complex noise (a 6 MHz 8-VSB-like DTV channel surrogate) + receiver noise
    surveillance s[n]  direct path + static clutter + a delayed, Doppler-shifted target echo + noise
    ECA                s <- s - sum_l w_l r[n - l],  w = argmin ||s - X w||^2 (least squares, l = 0..K-1)
    CAF                chi(l, f_D) = sum_n s[n] conj(r[n - l]) exp(-j 2 pi f_D n / f_s)   (batches algorithm)
    CA-CFAR            |chi|^2 > (Pfa^(-1/N) - 1) * sum(training cells), zero-Doppler bins excluded
    candidates         CFAR cells that are 3x3 local maxima -> (bistatic range, Doppler, strength)

Conventions (as everywhere in the workbench, :mod:`workbench.bistatic`): lag ``l`` is the *excess*
path delay, ``R = c l / f_s`` (the direct path sits at ``l = 0``); an echo ``r[n - l] exp(+j 2 pi f_D n / f_s)``
peaks at ``+f_D``, and ``Rdot = -lambda f_D`` (positive Doppler = approaching).

All heavy steps are whole-array FFTs (``scipy.fft`` with ``workers``); there is no Python loop over
range or Doppler bins.  The per-frame loop of :func:`simulate_scans` is over frames only (each frame
is a 2.5 M-sample computation at the default 10 MHz, 0.25 s).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft
from scipy import linalg as slinalg
from scipy import ndimage

from workbench.sensing.bistatic import SPEED_OF_LIGHT, doppler_to_range_rate, range_rate_to_doppler, wavelength
from workbench.types import CLUTTER, InputError, Scans

__all__ = [
    "PCLConfig",
    "SignalScene",
    "CAFMap",
    "Candidates",
    "dtv_reference_spectrum",
    "frame_signals",
    "eca",
    "caf_batches",
    "box_sum",
    "ca_cfar",
    "cfar_candidates",
    "process_frame",
    "simulate_scans",
]


def _workers() -> int:
    return max(1, min(os.cpu_count() or 1, 8))


@dataclass(frozen=True)
class PCLConfig:
    """Receiver and processing parameters of one frame.

    ``batch_length`` is the batch length ``M`` of the batches algorithm: the Doppler grid spacing is
    ``f_s / (M B) = 1 / CPI`` and the unambiguous span ``+-f_s / (2 M)`` (500 Hz at the defaults, far
    beyond the +-117 Hz of +-50 m/s).
    """

    sample_rate: float = 10e6
    cpi: float = 0.25
    frequency_hz: float = 701e6
    bandwidth: float = 6e6
    rolloff: float = 0.115
    range_max: float = 3000.0
    range_rate_max: float = 50.0
    batch_length: int = 10_000
    eca_taps: int = 16
    pfa: float = 1e-4
    guard: tuple[int, int] = (2, 2)  # (range, Doppler) guard cells on each side of the cell under test
    train: tuple[int, int] = (8, 8)  # training cells beyond the guard cells, on each side
    zero_doppler_bins: int = 1  # exclude |f_D| < zero_doppler_bins bins (= the k = 0 bin for 1)
    doppler_window: str = "hamming"

    def __post_init__(self) -> None:
        if self.sample_rate <= 0 or self.cpi <= 0 or self.range_max <= 0 or self.range_rate_max <= 0:
            raise InputError(f"PCLConfig: sample_rate, cpi, range_max and range_rate_max must be > 0: {self}")
        if not 0 < self.pfa < 1:
            raise InputError(f"PCLConfig: pfa must be in (0, 1), got {self.pfa}")
        if self.batches < 2:
            raise InputError(f"PCLConfig: the CPI holds {self.samples} samples, fewer than two batches of "
                             f"{self.batch_length}")
        if self.doppler_window not in ("hamming", "none"):
            raise InputError(f"PCLConfig: doppler_window must be 'hamming' or 'none', got {self.doppler_window!r}")

    @property
    def samples(self) -> int:
        """Samples per CPI, ``N = round(f_s CPI)``, rounded down to whole batches."""
        return self.batches * self.batch_length

    @property
    def batches(self) -> int:
        return int(round(self.sample_rate * self.cpi)) // self.batch_length

    @property
    def range_bin(self) -> float:
        """``c / f_s`` (m): 29.98 m at 10 MHz."""
        return SPEED_OF_LIGHT / self.sample_rate

    @property
    def lags(self) -> int:
        """Number of range bins ``0 .. ceil(range_max / range_bin)``."""
        return int(np.ceil(self.range_max / self.range_bin)) + 1

    @property
    def doppler_bin(self) -> float:
        """``1 / CPI`` (Hz)."""
        return self.sample_rate / self.samples

    @property
    def wavelength(self) -> float:
        return wavelength(self.frequency_hz)

    @property
    def doppler_half(self) -> int:
        """``K``: Doppler bins ``-K..K`` cover ``+-range_rate_max``."""
        return int(np.ceil(self.range_rate_max / self.wavelength / self.doppler_bin))

    @property
    def range_axis(self) -> np.ndarray:
        return self.range_bin * np.arange(self.lags)

    @property
    def doppler_axis(self) -> np.ndarray:
        return self.doppler_bin * np.arange(-self.doppler_half, self.doppler_half + 1)


@dataclass(frozen=True)
class SignalScene:
    """What the surveillance channel sees, in dB relative to its receiver noise (unit power).

    The static clutter patches are zero-Doppler reflectors at the given bistatic ranges.
    """

    target_db: float = -20.0
    direct_path_db: float = 30.0
    clutter_ranges: tuple[float, ...] = (30.0, 75.0, 150.0, 240.0, 390.0)
    clutter_db: tuple[float, ...] = (20.0, 15.0, 12.0, 8.0, 5.0)
    reference_snr_db: float = 40.0

    def __post_init__(self) -> None:
        if len(self.clutter_ranges) != len(self.clutter_db):
            raise InputError("SignalScene: clutter_ranges and clutter_db must have the same length")


@dataclass(frozen=True)
class CAFMap:
    """A cross-ambiguity map.

    Shapes: ``chi (L, D)`` complex, ``range_m (L,)``, ``doppler_hz (D,)``.
    """

    chi: np.ndarray
    range_m: np.ndarray
    doppler_hz: np.ndarray

    @property
    def power(self) -> np.ndarray:
        return (self.chi.real ** 2 + self.chi.imag ** 2).astype(float)


@dataclass(frozen=True)
class Candidates:
    """Candidates extracted from one map.  Shapes: every field ``(C,)``."""

    range_m: np.ndarray
    doppler_hz: np.ndarray
    range_rate: np.ndarray
    strength_db: np.ndarray
    range_index: np.ndarray
    doppler_index: np.ndarray


# -- signals ------------------------------------------------------------------------------------------


def dtv_reference_spectrum(n: int, sample_rate: float, bandwidth: float, rng: np.random.Generator,
                           rolloff: float = 0.115) -> np.ndarray:
    """Spectrum (length ``n`` FFT, complex64) of a unit-power noise-like DTV surrogate.

    Complex Gaussian with a raised-cosine power spectrum occupying ``|f| <= bandwidth / 2`` (flat to
    ``(1 - rolloff) bandwidth / 2``; 8-VSB uses a root-raised-cosine pulse with roll-off 0.115), so the
    range autocorrelation decays quickly instead of the slow sinc of a brick-wall band.
    """
    f = np.abs(sfft.fftfreq(n, 1.0 / sample_rate))
    edge = 0.5 * bandwidth
    flat = (1.0 - rolloff) * edge
    # raised-cosine power: 1 below flat, cos^2 taper to 0 at the band edge
    taper = np.clip((f - flat) / max(edge - flat, 1e-12), 0.0, 1.0)
    power = np.where(f <= edge, np.cos(0.5 * np.pi * taper) ** 2, 0.0)
    g = rng.standard_normal((2, n), dtype=np.float32)
    # unit time-domain power: sum |X_k|^2 = n^2 (Parseval with numpy's unnormalised FFT)
    amp = np.sqrt(power * n * n / (2.0 * power.sum())).astype(np.float32)
    return (g[0] + 1j * g[1]) * amp


def _cis(phase: np.ndarray) -> np.ndarray:
    """``exp(j phase)`` as complex64 (cos and sin separately: several times faster than complex exp)."""
    out = np.empty(phase.shape, dtype=np.complex64)
    out.real = np.cos(phase)
    out.imag = np.sin(phase)
    return out


def _amp(db: float) -> float:
    return 10.0 ** (db / 20.0)


def frame_signals(targets, rng: np.random.Generator, config: PCLConfig = PCLConfig(),
                  scene: SignalScene = SignalScene()) -> tuple[np.ndarray, np.ndarray]:
    """Reference and surveillance samples of one CPI.

    ``targets (K, 2)`` holds ``[R, Rdot]`` (m, m/s) of each moving echo.  Each echo is the reference
    delayed by ``R / c`` (fractional delays applied exactly in the frequency domain on a band-limited
    signal with enough history) and multiplied by ``exp(+j 2 pi f_D n / f_s)`` with ``f_D = -Rdot / lambda``.
    The direct path (delay 0) and the static clutter patches share one inverse FFT.

    Returns ``ref (N,)`` and ``surv (N,)`` complex64 (surveillance noise of unit power).
    """
    targets = np.atleast_2d(np.asarray(targets, dtype=float)).reshape(-1, 2)
    n = config.samples
    fs = config.sample_rate
    clutter_tau = np.asarray(scene.clutter_ranges, dtype=float) / SPEED_OF_LIGHT
    delays = np.concatenate([targets[:, 0] / SPEED_OF_LIGHT, clutter_tau])
    if np.any(delays < 0):
        raise InputError("frame_signals: bistatic ranges must be >= 0")
    pad = int(np.ceil(delays.max(initial=0.0) * fs)) + 64  # history so that delayed copies are causal
    total = sfft.next_fast_len(n + pad)
    spec = dtv_reference_spectrum(total, fs, config.bandwidth, rng, config.rolloff)
    two_pi_f = 2.0 * np.pi * sfft.fftfreq(total, 1.0 / fs)
    w = _workers()

    def delayed(gain: np.ndarray) -> np.ndarray:
        return sfft.ifft(spec * gain, workers=w)[pad:pad + n]

    r = sfft.ifft(spec, workers=w)[pad:pad + n]
    # static part: direct path (delay 0) + zero-Doppler clutter, a_dp + sum_c a_c exp(-j 2 pi f tau_c)
    static_gain = np.full(total, _amp(scene.direct_path_db), dtype=np.complex64)
    for tau, db in zip(clutter_tau, scene.clutter_db):  # a handful of patches, each a whole-array term
        static_gain += np.float32(_amp(db)) * _cis(-two_pi_f * tau)
    surv = delayed(static_gain)
    two_pi_t = 2.0 * np.pi * np.arange(n) / fs
    for R, rdot in targets:
        f_d = range_rate_to_doppler(rdot, config.wavelength)
        # echo: a_t r(t - R/c) exp(+j 2 pi f_D t)
        echo = delayed(np.float32(_amp(scene.target_db)) * _cis(-two_pi_f * (R / SPEED_OF_LIGHT)))
        surv += echo * _cis(two_pi_t * f_d)
    noise = rng.standard_normal((4, n), dtype=np.float32) * np.float32(np.sqrt(0.5))
    surv += noise[0] + 1j * noise[1]
    ref = r + (noise[2] + 1j * noise[3]) * np.float32(1.0 / _amp(scene.reference_snr_db))
    return ref.astype(np.complex64), surv.astype(np.complex64)


# -- cancellation ---------------------------------------------------------------------------------------


def eca(surv: np.ndarray, ref: np.ndarray, taps: int) -> tuple[np.ndarray, np.ndarray]:
    """Extensive cancellation algorithm: remove ``taps`` zero-Doppler delayed copies of the reference.

    ``w = argmin_w ||s - X w||^2`` with ``X[n, l] = r[n - l]`` (``r[n < 0] = 0``), ``l = 0 .. taps-1``;
    the normal equations ``(X^H X) w = X^H s`` are formed with FFT correlations (``X^H X`` as the
    Hermitian Toeplitz matrix of the reference autocorrelation) and solved by Cholesky.

    Returns the cleaned surveillance ``(N,)`` and the weights ``(taps,)``.
    """
    if taps < 1:
        return surv, np.zeros(0, dtype=complex)
    n = surv.shape[0]
    nfft = sfft.next_fast_len(n + taps)
    w = _workers()
    Rf = sfft.fft(ref, nfft, workers=w)
    Sf = sfft.fft(surv, nfft, workers=w)
    # c[d] = sum_m conj(r[m]) r[m + d];  b[i] = sum_m conj(r[m]) s[m + i]
    c = sfft.ifft(np.conj(Rf) * Rf, workers=w)[:taps].astype(complex)
    b = sfft.ifft(np.conj(Rf) * Sf, workers=w)[:taps].astype(complex)
    # (X^H X)[i, j] = c[i - j]  (Toeplitz, Hermitian)
    gram = slinalg.toeplitz(c, np.conj(c))
    weights = slinalg.solve(gram, b, assume_a="pos")
    # s_clean[n] = s[n] - sum_l w_l r[n - l]
    fit = sfft.ifft(Rf * sfft.fft(weights, nfft), workers=w)[:n]
    return (surv - fit).astype(surv.dtype), weights


# -- cross-ambiguity function ----------------------------------------------------------------------------


def caf_batches(surv: np.ndarray, ref: np.ndarray, config: PCLConfig = PCLConfig()) -> CAFMap:
    """Cross-ambiguity function on the range-Doppler grid of ``config`` by the batches algorithm.

    Split the CPI into ``B`` batches of ``M`` samples; per batch, the correlation over lags
    ``l = 0..L-1`` by FFT, ``c_b[l] = sum_m s[bM + m + l] conj(r[bM + m])``; then an FFT across batches
    (optionally Hamming-windowed) gives ``chi(l, k) = sum_b c_b[l] exp(-j 2 pi k b / B)`` at
    ``f_D = k / CPI``, ``k = -K..K``.

    Shapes: ``surv, ref (N,)`` with ``N = config.samples``; result ``chi (L, 2K + 1)``.
    """
    n, M, B, L, K = config.samples, config.batch_length, config.batches, config.lags, config.doppler_half
    if surv.shape != (n,) or ref.shape != (n,):
        raise InputError(f"caf_batches: expected signals of {n} samples, got {surv.shape} and {ref.shape}")
    w = _workers()
    nfft = sfft.next_fast_len(M + L - 1)
    # surveillance segments of length M + L - 1 starting at b M (zero-padded past the end)
    s_pad = np.concatenate([surv, np.zeros(L - 1, dtype=surv.dtype)])
    segments = np.lib.stride_tricks.sliding_window_view(s_pad, M + L - 1)[::M][:B]
    S = sfft.fft(segments, nfft, axis=1, workers=w)
    Rb = sfft.fft(ref.reshape(B, M), nfft, axis=1, workers=w)
    # c_b[l] = sum_m s[bM + m + l] conj(r[bM + m])
    corr = sfft.ifft(S * np.conj(Rb), axis=1, workers=w)[:, :L]
    if config.doppler_window == "hamming":
        corr = corr * np.hamming(B).astype(corr.real.dtype)[:, None]
    # chi(l, k) = sum_b c_b[l] exp(-j 2 pi k b / B)
    dop = sfft.fft(corr, axis=0, workers=w)
    keep = np.r_[B - K:B, 0:K + 1]
    return CAFMap(np.ascontiguousarray(dop[keep].T), config.range_axis, config.doppler_axis)


# -- CFAR -----------------------------------------------------------------------------------------------


def box_sum(x: np.ndarray, half: tuple[int, int]) -> np.ndarray:
    """Sum of ``x (L, D)`` over the ``(2 h0 + 1) x (2 h1 + 1)`` box centred on every cell (zero outside).

    Integral image (2-D cumulative sums): four look-ups per cell, no loop over cells.
    """
    h0, h1 = half
    L, D = x.shape
    ii = np.zeros((L + 1, D + 1))
    ii[1:, 1:] = np.cumsum(np.cumsum(x, axis=0), axis=1)
    r0 = np.clip(np.arange(L) - h0, 0, L)
    r1 = np.clip(np.arange(L) + h0 + 1, 0, L)
    c0 = np.clip(np.arange(D) - h1, 0, D)
    c1 = np.clip(np.arange(D) + h1 + 1, 0, D)
    return ii[r1][:, c1] - ii[r0][:, c1] - ii[r1][:, c0] + ii[r0][:, c0]


def ca_cfar(power: np.ndarray, pfa: float, guard=(2, 2), train=(8, 8), usable: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """Cell-averaging CFAR on a square-law map.

    For every cell the training set is the window of half-size ``guard + train`` minus the guard
    window of half-size ``guard`` (both including the cell under test's row/column), restricted to
    ``usable`` cells; with ``N`` training cells (fewer at the edges) the threshold is
    ``T = alpha / N * sum(training)``, ``alpha = N (Pfa^(-1/N) - 1)``, which gives exactly ``Pfa`` for
    i.i.d. exponential noise.

    Shapes: ``power (L, D)``; ``usable (L, D)`` bool (default all).  Returns ``detections (L, D)`` bool
    and ``noise (L, D)``, the training mean (inf where a cell has no training cells).
    """
    power = np.asarray(power, dtype=float)
    usable = np.ones(power.shape, dtype=bool) if usable is None else np.asarray(usable, dtype=bool)
    outer = (guard[0] + train[0], guard[1] + train[1])
    masked = np.where(usable, power, 0.0)
    total = box_sum(masked, outer) - box_sum(masked, tuple(guard))
    count = np.rint(box_sum(usable.astype(float), outer) - box_sum(usable.astype(float), tuple(guard)))
    with np.errstate(divide="ignore", invalid="ignore"):
        noise = np.where(count > 0, total / np.maximum(count, 1), np.inf)
        # T = (Pfa^(-1/N) - 1) * sum(training)
        factor = np.where(count > 0, pfa ** (-1.0 / np.maximum(count, 1)) - 1.0, np.inf)
    threshold = factor * total
    return (power > threshold) & (count > 0), noise


def _parabolic(lo: np.ndarray, mid: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Peak offset in bins of a parabola through three (log) samples, clipped to [-0.5, 0.5]."""
    den = lo - 2.0 * mid + hi
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den < 0, 0.5 * (lo - hi) / den, 0.0)
    return np.clip(np.nan_to_num(off), -0.5, 0.5)


def cfar_candidates(caf: CAFMap, config: PCLConfig = PCLConfig()) -> tuple[Candidates, np.ndarray]:
    """CA-CFAR detections that are 3x3 local maxima, outside the zero-Doppler bins.

    The zero-Doppler bins (``|k| < zero_doppler_bins``) are neither detected nor used as training
    cells (the direct-path / clutter residue lives there).  Range and Doppler are refined by a
    parabola through the dB power of the neighbouring bins.  Returns the candidates and the
    ``(L, D)`` detection mask.
    """
    power = caf.power
    k = np.arange(power.shape[1]) - (power.shape[1] // 2)
    usable = np.broadcast_to(np.abs(k) >= config.zero_doppler_bins, power.shape)
    detect, noise = ca_cfar(power, config.pfa, config.guard, config.train, usable)
    peak = power >= ndimage.maximum_filter(power, size=3, mode="constant", cval=0.0)
    mask = detect & peak & usable
    li, di = np.nonzero(mask)
    logp = 10.0 * np.log10(np.maximum(power, 1e-300))
    Lmax, Dmax = power.shape[0] - 1, power.shape[1] - 1
    inner_l = (li > 0) & (li < Lmax)
    inner_d = (di > 0) & (di < Dmax)
    dl = np.where(inner_l, _parabolic(logp[np.maximum(li - 1, 0), di], logp[li, di],
                                      logp[np.minimum(li + 1, Lmax), di]), 0.0)
    dd = np.where(inner_d, _parabolic(logp[li, np.maximum(di - 1, 0)], logp[li, di],
                                      logp[li, np.minimum(di + 1, Dmax)]), 0.0)
    range_m = caf.range_m[li] + dl * config.range_bin
    doppler = caf.doppler_hz[di] + dd * config.doppler_bin
    strength = 10.0 * np.log10(power[li, di] / noise[li, di])
    cands = Candidates(range_m, doppler, doppler_to_range_rate(doppler, config.wavelength), strength, li, di)
    return cands, mask


def process_frame(ref: np.ndarray, surv: np.ndarray, config: PCLConfig = PCLConfig(), cancel: bool = True
                  ) -> tuple[CAFMap, Candidates, np.ndarray]:
    """ECA (optional) -> CAF -> CFAR candidates for one CPI."""
    if cancel:
        surv, _ = eca(surv, ref, config.eca_taps)
    caf = caf_batches(surv, ref, config)
    cands, mask = cfar_candidates(caf, config)
    return caf, cands, mask


def simulate_scans(truth_rr: np.ndarray, times: np.ndarray, rng: np.random.Generator,
                   config: PCLConfig = PCLConfig(), scene: SignalScene = SignalScene()) -> Scans:
    """Signal-level candidates for target tracks ``truth_rr (B, T, 2)`` of ``[R, Rdot]``: a :class:`Scans`.

    Same output as the detection-level sensor: ``z = [R, Rdot]``, ``doppler`` (Hz), ``snr`` (strength,
    dB).  The candidate nearest the true target cell, within 1.5 range and 1.5 Doppler bins, is
    labelled as the target (origin 0); every other candidate is clutter.
    """
    truth_rr = np.asarray(truth_rr, dtype=float)
    if truth_rr.ndim != 3 or truth_rr.shape[-1] != 2:
        raise InputError(f"simulate_scans expects truth (B, T, 2), got {truth_rr.shape}")
    B, T, _ = truth_rr.shape
    frames = [[None] * T for _ in range(B)]
    for b in range(B):
        for t in range(T):  # one frame is a whole-array FFT computation of N samples
            ref, surv = frame_signals(truth_rr[b, t][None], rng, config, scene)
            _, cands, _ = process_frame(ref, surv, config)
            frames[b][t] = cands
    M = max([len(c.range_m) for row in frames for c in row], default=0)
    z = np.zeros((B, T, M, 2))
    valid = np.zeros((B, T, M), dtype=bool)
    snr = np.full((B, T, M), np.nan)
    dop = np.full((B, T, M), np.nan)
    origin = np.full((B, T, M), CLUTTER, dtype=int)
    f_true = range_rate_to_doppler(truth_rr[..., 1], config.wavelength)
    for b in range(B):
        for t in range(T):
            c = frames[b][t]
            m = len(c.range_m)
            z[b, t, :m, 0], z[b, t, :m, 1] = c.range_m, c.range_rate
            valid[b, t, :m] = True
            snr[b, t, :m], dop[b, t, :m] = c.strength_db, c.doppler_hz
            dr = np.abs(c.range_m - truth_rr[b, t, 0]) / config.range_bin
            dd = np.abs(c.doppler_hz - f_true[b, t]) / config.doppler_bin
            near = (dr <= 1.5) & (dd <= 1.5)
            if near.any():
                origin[b, t, np.argmin(np.where(near, dr * dr + dd * dd, np.inf))] = 0
    return Scans(z, valid, np.asarray(times, dtype=float), snr=snr, doppler=dop, origin=origin)
