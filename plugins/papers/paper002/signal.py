"""Signal-level passive coherent location (PCL): DTV signals, ECA, the cross-ambiguity function, CA-CFAR.

Pipeline of one frame (one coherent processing interval, CPI)::

    reference r[n]     the illuminator: band-limited complex noise (the benign scene) or an ATSC 8-VSB
                       channel with pilot, segment and field syncs (the demanding scene, :mod:`.atsc`)
    surveillance s[n]  direct path + static clutter + a delayed, Doppler-shifted target echo + noise
    ECA                s <- s - sum_l w_l r[n - l],  w = argmin ||s - X w||^2 (least squares, l = 0..K-1)
    pilot removal      r <- r - a_b exp(j w_p m) per batch (8-VSB: the pilot carrier would otherwise give a
                       ridge over every range at the target's Doppler)
    CAF                chi(l, f_D) = sum_n s[n] conj(r[n - l]) exp(-j 2 pi f_D n / f_s)   (batches algorithm)
    CA-CFAR            |chi|^2 > (Pfa^(-1/N) - 1) * sum(training cells), zero-Doppler bins excluded
    candidates         CFAR cells that are 3x3 local maxima -> (bistatic range, Doppler, strength)

Two implementations of ECA + CAF compute the same map:

- **folded** (:func:`batch_spectra`, :func:`eca_weights`, :func:`caf_folded`; what :func:`process_frame` runs):
  single precision, everything on the per-batch spectra of the batches algorithm.  The ECA normal equations
  come from the same batch spectra (``X^H s`` and the reference autocorrelation are sums over batches of
  per-batch correlations), and the fit is subtracted from each batch's surveillance spectrum before the
  correlation (``(S_b - W E_b) conj(R_b)``, ``E_b`` the spectrum of the reference segment reaching ``K - 1``
  samples back).  Four FFTs of ``B x F`` points (``F = 10240``, a fast length) instead of full-length FFTs of
  2.5 M points;
- **reference** (:func:`eca`, :func:`remove_pilot`, :func:`caf_batches`): the NumPy twin, in whatever precision
  its input has (complex128 in the tests and the benchmark's accuracy check): ECA on the whole CPI with
  full-length FFTs, then the batches CAF.

Conventions (as everywhere in the workbench, :mod:`workbench.sensing.bistatic`): lag ``l`` is the *excess*
path delay, ``R = c l / f_s`` (the direct path sits at ``l = 0``); an echo ``r[n - l] exp(+j 2 pi f_D n / f_s)``
peaks at ``+f_D``, and ``Rdot = -lambda f_D`` (positive Doppler = approaching).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from scipy import fft as sfft
from scipy import linalg as slinalg
from scipy import ndimage

from workbench.sensing.bistatic import SPEED_OF_LIGHT, doppler_to_range_rate, range_rate_to_doppler, wavelength
from workbench.types import CLUTTER, InputError, Scans

from . import atsc
from .fold import clean_product, normal_sums

__all__ = [
    "PCLConfig",
    "SignalScene",
    "BENIGN_SCENE",
    "DEMANDING_SCENE",
    "demanding_config",
    "CAFMap",
    "Candidates",
    "BatchSpectra",
    "fast_length",
    "dtv_reference_spectrum",
    "frame_signals",
    "eca",
    "cleaning_weights",
    "CLEANING_ROW_STEP",
    "usable_cores",
    "cleaning_filter",
    "clean_reference",
    "DEMANDING_ECA_TAPS",
    "DEMANDING_CLUTTER_MAX",
    "DEMANDING_CPI",
    "DEMANDING_CLEANING",
    "remove_pilot",
    "pilot_spectral",
    "caf_batches",
    "batch_spectra",
    "eca_weights",
    "caf_folded",
    "box_sum",
    "ca_cfar",
    "cfar_candidates",
    "process_frame",
    "simulate_scans",
    "simulate_scans_multi",
]


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the platform tells it, else ``os.cpu_count``)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def _workers() -> int:
    return max(1, min(usable_cores(), 8))


def fast_length(n: int) -> int:
    """The smallest ``2^a * c >= n`` with ``c`` in {1, 3, 5, 9, 15, 25}: the lengths pocketfft transforms fastest.

    (``scipy.fft.next_fast_len`` also accepts 7- and 11-smooth lengths such as 10125, which take 1.7 times as
    long as 10240 here.)
    """
    best = None
    for c in (1, 3, 5, 9, 15, 25):
        m = c
        while m < n:
            m *= 2
        best = m if best is None else min(best, m)
    return int(best)


@dataclass(frozen=True)
class PCLConfig:
    """Receiver and processing parameters of one frame.

    ``batch_length`` is the batch length ``M`` of the batches algorithm: the Doppler grid spacing is
    ``f_s / (M B) = 1 / CPI`` and the unambiguous span ``+-f_s / (2 M)`` (500 Hz at the defaults, far
    beyond the +-117 Hz of +-50 m/s).  ``eca_taps`` (``K``, at most ``batch_length``) zero-Doppler taps are
    cancelled (``K`` may exceed the map's range bins: clutter beyond the map's edge is cancelled too);
    ``eca_loading`` is the diagonal loading of the ECA normal equations relative to their mean diagonal (the
    single-precision Gram matrix cannot resolve eigenvalues below about 1e-7 of the largest; the reference
    channel's out-of-band noise sits there).  ``pilot_hz``: the frequency of a pilot carrier of the illuminator
    (8-VSB: ``-R_s / 4`` from the channel centre), removed from the reference batches before the correlation
    where ``pilot_removal`` (and known to the cleaning stage either way); ``None`` for a waveform without one.
    ``cleaning_taps`` (``K_c``, 0: no cleaning), ``cleaning_delay`` (``D``) and ``cleaning_loading``: the
    reference-cleaning stage (:func:`cleaning_weights`), a delayed linear predictor over lags
    ``D .. D + K_c - 1`` fitted on the CPI and applied to it.
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
    eca_loading: float = 1e-6
    pilot_hz: float | None = None
    pilot_removal: bool = True
    cleaning_taps: int = 0
    cleaning_delay: int = 8
    cleaning_loading: float = 1e-3
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
        if not 0 <= self.eca_taps <= self.batch_length:
            raise InputError(f"PCLConfig: eca_taps must be in 0..{self.batch_length} (the batch length), "
                             f"got {self.eca_taps}")
        if self.cleaning_taps < 0 or self.cleaning_delay < 1 or self.cleaning_loading < 0:
            raise InputError(f"PCLConfig: cleaning_taps must be >= 0, cleaning_delay >= 1 and cleaning_loading "
                             f">= 0, got {self.cleaning_taps}, {self.cleaning_delay}, {self.cleaning_loading}")
        if self.cleaning_memory > self.batch_length:
            raise InputError(f"PCLConfig: the cleaning filter's span cleaning_delay + cleaning_taps - 1 = "
                             f"{self.cleaning_memory} exceeds the batch length {self.batch_length}")
        if self.eca_loading < 0:
            raise InputError(f"PCLConfig: eca_loading must be >= 0, got {self.eca_loading}")

    @property
    def samples(self) -> int:
        """Samples per CPI, ``N = round(f_s CPI)``, rounded down to whole batches."""
        return self.batches * self.batch_length

    @property
    def batches(self) -> int:
        return int(round(self.sample_rate * self.cpi)) // self.batch_length

    @property
    def cleaning_memory(self) -> int:
        """``Q = D + K_c - 1``: how far back the cleaning filter reaches (0 without cleaning)."""
        return self.cleaning_delay + self.cleaning_taps - 1 if self.cleaning_taps else 0

    def span(self, taps: int | None = None) -> int:
        """``max(L, K)``: the lags the surveillance segments of the folded chain must reach (the map's ``L`` for
        the correlation, ``K`` for the ECA normal equations)."""
        return max(self.lags, self.eca_taps if taps is None else int(taps))

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

    def fft_length(self, taps: int | None = None) -> int:
        """Per-batch FFT length of the folded chain: :func:`fast_length` of ``M + max(L, K) + K - 2 + 2 Q``
        (``Q``: :attr:`cleaning_memory`; 10240 at the defaults for any ``K <= L``, 12288 for the demanding
        scene's 600 taps and 128 cleaning taps)."""
        k = self.eca_taps if taps is None else int(taps)
        # 2 Q: the segments of the cleaning stage reach Q further back, and their autocorrelation is read to lag Q
        return fast_length(self.batch_length + self.span(k) + max(k, 1) - 2 + 2 * self.cleaning_memory)

    @property
    def cells(self) -> int:
        """Cells the CFAR searches: range bins x Doppler bins outside the zero-Doppler notch."""
        return self.lags * (2 * self.doppler_half + 1 - (2 * self.zero_doppler_bins - 1))


@dataclass(frozen=True)
class SignalScene:
    """What the surveillance channel sees, in dB relative to its receiver noise (unit power).

    The static clutter patches are zero-Doppler reflectors at the given bistatic ranges.  ``waveform`` is the
    illuminator: ``"noise"`` (band-limited complex Gaussian, the brief's surrogate) or ``"atsc"`` (ATSC 8-VSB,
    :mod:`.atsc`, at ``symbol_rate``: A/53's by default, a scaled one for small test configurations);
    ``reference_snr_db`` is the reference channel's signal-to-noise ratio.  ``reference_multipath_ranges`` (m of
    excess path) and ``reference_multipath_db`` (dB relative to the reference channel's direct signal): delayed
    copies of the transmitted signal that the reference antenna receives besides the direct one (the
    surveillance channel's echoes are copies of the transmitted signal, not of the received reference).
    """

    target_db: float = -20.0
    direct_path_db: float = 30.0
    clutter_ranges: tuple[float, ...] = (30.0, 75.0, 150.0, 240.0, 390.0)
    clutter_db: tuple[float, ...] = (20.0, 15.0, 12.0, 8.0, 5.0)
    reference_snr_db: float = 40.0
    waveform: str = "noise"
    symbol_rate: float = atsc.SYMBOL_RATE
    reference_multipath_ranges: tuple[float, ...] = ()
    reference_multipath_db: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if len(self.clutter_ranges) != len(self.clutter_db):
            raise InputError("SignalScene: clutter_ranges and clutter_db must have the same length")
        if len(self.reference_multipath_ranges) != len(self.reference_multipath_db):
            raise InputError("SignalScene: reference_multipath_ranges and reference_multipath_db must have the same "
                             "length")
        if any(r <= 0 for r in self.reference_multipath_ranges):
            raise InputError(f"SignalScene: reference_multipath_ranges must be > 0 m, got "
                             f"{self.reference_multipath_ranges}")
        if self.waveform not in ("noise", "atsc"):
            raise InputError(f"SignalScene: waveform must be 'noise' or 'atsc', got {self.waveform!r}")


#: The brief's signal-level scene (the paper's row): noise-like reference, direct path +30 dB, clutter within 390 m.
BENIGN_SCENE = SignalScene()

_DEMANDING_RANGES = (30.0, 90.0, 180.0, 300.0, 450.0, 650.0, 900.0, 1200.0, 1500.0, 1800.0, 2100.0, 2400.0, 2700.0,
                     2950.0, 3600.0, 4800.0, 6500.0, 8500.0, 10500.0, 12500.0, 14500.0, 16000.0, 17500.0)
#: How far the demanding scene's clutter reaches (m of bistatic range).
DEMANDING_CLUTTER_MAX = 17_500.0
#: The demanding scene's ECA span: zero-Doppler taps 0 .. 17.96 km at 10 MHz, past the farthest clutter.
DEMANDING_ECA_TAPS = 600
#: The demanding scene's coherent interval: the detection level's 0.5 s.
DEMANDING_CPI = 0.5
#: The reference-cleaning predictor of the demanding scene: lags 8 .. 135 (240 m - 4 km of excess path: the
#: multipath and its first multiples, which the inverse of the reference channel holds).
DEMANDING_CLEANING = {"cleaning_taps": 128, "cleaning_delay": 8}
#: A demanding scene: ATSC 8-VSB illuminator, direct path +60 dB, 23 clutter patches from 30 m to 17.5 km (the
#: map shows 0-3 km; the clutter beyond it reaches the surveillance channel all the same) whose clutter-to-noise
#: ratio falls linearly with range from +50 dB to +30 dB, a reference channel at 70 dB SNR that also receives the
#: transmitter over three longer paths (300 m, 750 m and 1.5 km of excess path at -10, -14 and -18 dB).
DEMANDING_SCENE = SignalScene(
    direct_path_db=60.0,
    clutter_ranges=_DEMANDING_RANGES,
    clutter_db=tuple(round(50.0 - 20.0 * (r - 30.0) / (DEMANDING_CLUTTER_MAX - 30.0), 2) for r in _DEMANDING_RANGES),
    reference_snr_db=70.0,
    waveform="atsc",
    reference_multipath_ranges=(300.0, 750.0, 1500.0),
    reference_multipath_db=(-10.0, -14.0, -18.0),
)


def demanding_config(base: PCLConfig = PCLConfig(), scene: SignalScene = DEMANDING_SCENE, *,
                     taps: int = DEMANDING_ECA_TAPS, cpi: float = DEMANDING_CPI, cleaning: bool = True) -> PCLConfig:
    """The processing for :data:`DEMANDING_SCENE`: as ``base``, with a CPI of ``cpi`` (the detection level's 0.5 s),
    ``taps`` zero-Doppler ECA taps (600: 0 - 17.96 km at 10 MHz, past the farthest clutter; the rule: cancel
    every lag at which the scene holds clutter, on the map or beyond it), the reference cleaned
    (:data:`DEMANDING_CLEANING`, :func:`cleaning_weights`) and the 8-VSB pilot (nominally ``-R_s / 4`` from the
    channel centre) removed from the reference."""
    extra = DEMANDING_CLEANING if cleaning else {"cleaning_taps": 0}
    return replace(base, cpi=cpi, eca_taps=int(taps), pilot_hz=atsc.pilot_offset_hz(scene.symbol_rate), **extra)


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
        return (self.chi.real.astype(float) ** 2 + self.chi.imag.astype(float) ** 2)


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
    g = rng.standard_normal((2, n), dtype=np.float32)
    return (g[0] + 1j * g[1]) * _dtv_amplitude(n, float(sample_rate), float(bandwidth), float(rolloff))


@lru_cache(maxsize=4)
def _dtv_amplitude(n: int, sample_rate: float, bandwidth: float, rolloff: float) -> np.ndarray:
    """The deterministic part of :func:`dtv_reference_spectrum`: the amplitude of each bin (float32, read-only;
    the same for every frame of a scene, so cached)."""
    f = np.abs(sfft.fftfreq(n, 1.0 / sample_rate))
    edge = 0.5 * bandwidth
    flat = (1.0 - rolloff) * edge
    # raised-cosine power: 1 below flat, cos^2 taper to 0 at the band edge
    taper = np.clip((f - flat) / max(edge - flat, 1e-12), 0.0, 1.0)
    power = np.where(f <= edge, np.cos(0.5 * np.pi * taper) ** 2, 0.0)
    # unit time-domain power: sum |X_k|^2 = n^2 (Parseval with numpy's unnormalised FFT)
    amp = np.sqrt(power * n * n / (2.0 * power.sum())).astype(np.float32)
    amp.setflags(write=False)
    return amp


def _cis(phase: np.ndarray) -> np.ndarray:
    """``exp(j phase)`` as complex64 (cos and sin separately: several times faster than complex exp)."""
    out = np.empty(phase.shape, dtype=np.complex64)
    out.real = np.cos(phase)
    out.imag = np.sin(phase)
    return out


_CIS_BLOCK = 1 << 16  # elements per block of :func:`_cis_ramp` (a block's temporaries stay in the cache)


def _cis_ramp(base: np.ndarray, scale: float, gain: float = 1.0, out: np.ndarray | None = None,
              add: bool = False) -> np.ndarray:
    """``gain * exp(j base * scale)`` (``base`` float32, ``scale`` and ``gain`` taken as float32), complex64, in
    blocks: element for element what ``np.float32(gain) * _cis(base * np.float32(scale))`` gives (the same
    float32 operations on each element), without whole-array temporaries.  With ``out`` the result is written
    (``add``: added) into it.  Shapes: ``base (N,)`` -> ``(N,)``."""
    scale, gain = np.float32(scale), np.float32(gain)
    if out is None:
        out = np.empty(base.shape, dtype=np.complex64)
    for lo in range(0, base.shape[0], _CIS_BLOCK):
        sl = slice(lo, lo + _CIS_BLOCK)
        phase = base[sl] * scale
        c = _cis(phase)
        if gain != 1.0:
            c *= gain
        if add:
            out[sl] += c
        else:
            out[sl] = c
    return out


def _amp(db: float) -> float:
    return 10.0 ** (db / 20.0)


@lru_cache(maxsize=4)
def _two_pi_f(total: int, sample_rate: float) -> np.ndarray:
    """``2 pi f`` of the FFT bins (rad/s), float32, read-only."""
    out = (2.0 * np.pi * sfft.fftfreq(total, 1.0 / sample_rate)).astype(np.float32)
    out.setflags(write=False)
    return out


@lru_cache(maxsize=4)
def _static_gain(total: int, sample_rate: float, direct_db: float, ranges: tuple, dbs: tuple) -> np.ndarray:
    """Transfer function of the static part of the surveillance channel, ``a_dp + sum_c a_c exp(-j 2 pi f tau_c)``.

    Stationary, so the same for every frame of a scene (cached).  Shapes: ``(total,)`` complex64, read-only.
    """
    two_pi_f = _two_pi_f(total, sample_rate)
    gain = np.full(total, _amp(direct_db), dtype=np.complex64)
    for R, db in zip(ranges, dbs):  # a handful of patches, each a whole-array term
        _cis_ramp(two_pi_f, -np.float32(R / SPEED_OF_LIGHT), _amp(db), out=gain, add=True)
    gain.setflags(write=False)
    return gain


@lru_cache(maxsize=4)
def _two_pi_t(n: int, sample_rate: float) -> np.ndarray:
    out = (2.0 * np.pi * np.arange(n) / sample_rate).astype(np.float32)
    out.setflags(write=False)
    return out


def frame_signals(targets, rng: np.random.Generator, config: PCLConfig = PCLConfig(),
                  scene: SignalScene = BENIGN_SCENE) -> tuple[np.ndarray, np.ndarray]:
    """Reference and surveillance samples of one CPI.

    ``targets (K, 2)`` holds ``[R, Rdot]`` (m, m/s) of each moving echo.  Each echo is the reference
    delayed by ``R / c`` (fractional delays applied exactly in the frequency domain on a band-limited
    signal with enough history) and multiplied by ``exp(+j 2 pi f_D n / f_s)`` with ``f_D = -Rdot / lambda``.
    The direct path (delay 0) and the static clutter patches share one inverse FFT.  The reference channel
    receives the transmitted signal directly and, when the scene has reference multipath, delayed copies of it
    (one more inverse FFT), plus its own noise.

    Returns ``ref (N,)`` and ``surv (N,)`` complex64 (surveillance noise of unit power).
    """
    targets = np.atleast_2d(np.asarray(targets, dtype=float)).reshape(-1, 2)
    n = config.samples
    fs = config.sample_rate
    clutter_tau = np.asarray(scene.clutter_ranges, dtype=float) / SPEED_OF_LIGHT
    multipath_tau = np.asarray(scene.reference_multipath_ranges, dtype=float) / SPEED_OF_LIGHT
    delays = np.concatenate([targets[:, 0] / SPEED_OF_LIGHT, clutter_tau, multipath_tau])
    if np.any(delays < 0):
        raise InputError("frame_signals: bistatic ranges must be >= 0")
    pad = int(np.ceil(delays.max(initial=0.0) * fs)) + 64  # history so that delayed copies are causal
    if scene.waveform == "atsc":
        if scene.symbol_rate * (1.0 + atsc.ROLLOFF) / 2.0 >= fs:
            raise InputError(f"frame_signals: an 8-VSB channel at {scene.symbol_rate:g} Bd does not fit in "
                             f"{fs:g} Hz of complex bandwidth")
        total, n_sym, _ = atsc.vsb_lengths(n + pad, fs, scene.symbol_rate)
        spec = atsc.vsb_spectrum(total, fs, rng, n_sym)
    else:
        total = sfft.next_fast_len(n + pad)
        spec = dtv_reference_spectrum(total, fs, config.bandwidth, rng, config.rolloff)
    two_pi_f = _two_pi_f(total, fs)
    w = _workers()

    def delayed(gain: np.ndarray) -> np.ndarray:
        # the product is a temporary: transformed in place (the same transform, without pocketfft's copy)
        return sfft.ifft(spec * gain, workers=w, overwrite_x=True)[pad:pad + n]

    if scene.reference_multipath_ranges:
        # the reference antenna's channel: 1 + sum_p a_p exp(-j 2 pi f tau_p)
        r = delayed(_static_gain(total, fs, 0.0, tuple(map(float, scene.reference_multipath_ranges)),
                                 tuple(map(float, scene.reference_multipath_db))))
    else:
        r = sfft.ifft(spec, workers=w)[pad:pad + n]
    # static part: direct path (delay 0) + zero-Doppler clutter, a_dp + sum_c a_c exp(-j 2 pi f tau_c)
    surv = delayed(_static_gain(total, fs, float(scene.direct_path_db), tuple(map(float, scene.clutter_ranges)),
                                tuple(map(float, scene.clutter_db))))
    two_pi_t = _two_pi_t(n, fs)
    for R, rdot in targets:
        f_d = range_rate_to_doppler(rdot, config.wavelength)
        # echo: a_t r(t - R/c) exp(+j 2 pi f_D t)
        echo = delayed(_cis_ramp(two_pi_f, -np.float32(R / SPEED_OF_LIGHT), _amp(scene.target_db)))
        doppler = _cis_ramp(two_pi_t, f_d)
        doppler *= echo
        surv += doppler
    # circular complex Gaussian noise, unit power in the surveillance channel: real and imaginary parts N(0, 1/2)
    noise = rng.standard_normal(4 * n, dtype=np.float32).view(np.complex64).reshape(2, n)
    noise *= np.float32(np.sqrt(0.5))
    surv += noise[0]
    noise[1] *= np.float32(1.0 / _amp(scene.reference_snr_db))
    ref = r + noise[1]
    return ref.astype(np.complex64, copy=False), surv.astype(np.complex64, copy=False)


# -- reference implementation (the NumPy twin): ECA on the whole CPI, pilot removal, batches CAF -------------


def eca(surv: np.ndarray, ref: np.ndarray, taps: int, loading: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Extensive cancellation algorithm: remove ``taps`` zero-Doppler delayed copies of the reference.

    ``w = argmin_w ||s - X w||^2`` with ``X[n, l] = r[n - l]`` (``r[n < 0] = 0``), ``l = 0 .. taps-1``;
    the normal equations ``(X^H X + delta I) w = X^H s`` are formed with FFT correlations (``X^H X`` as the
    Hermitian Toeplitz matrix of the reference autocorrelation, ``delta = loading * c[0]``) and solved by
    Cholesky.  Full-length FFTs in the input's precision: the reference the folded chain is held to.

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
    c = sfft.ifft(np.conj(Rf) * Rf, workers=w, overwrite_x=True)[:taps].astype(complex)
    b = sfft.ifft(np.conj(Rf) * Sf, workers=w, overwrite_x=True)[:taps].astype(complex)
    # (X^H X)[i, j] = c[i - j]  (Toeplitz, Hermitian)
    gram = slinalg.toeplitz(c, np.conj(c)) + loading * c[0].real * np.eye(taps)
    weights = slinalg.cho_solve(slinalg.cho_factor(gram), b)
    # s_clean[n] = s[n] - sum_l w_l r[n - l]
    fit = sfft.ifft(Rf * sfft.fft(weights, nfft), workers=w, overwrite_x=True)[:n]
    return (surv - fit).astype(surv.dtype), weights


def _cleaning_segments(ref: np.ndarray, config: PCLConfig, taps: int) -> tuple[np.ndarray, int, int]:
    """The raw reference segments the cleaning stage filters, transformed: row ``b`` holds
    ``x[bM - back - Q .. bM - back + length)`` (zero outside ``[0, N)``), ``back, length = K - 1, M + Ls + K - 2``
    with ``K = taps > 0`` (the extended segments of the folded ECA) or ``0, M`` (the batches).
    Returns ``X (B, F)`` complex64, ``back`` and ``length``."""
    M, B, K, Q = config.batch_length, config.batches, int(taps), config.cleaning_memory
    back, length = (K - 1, M + config.span(K) + K - 2) if K > 0 else (0, M)
    X = _segments(np.asarray(ref, dtype=np.complex64), B, M, length + Q, back + Q, config.fft_length(K))
    return sfft.fft(X, axis=1, workers=_workers(), overwrite_x=True), back, length


#: The cleaning stage's autocorrelation reads every ``CLEANING_ROW_STEP``-th segment of the CPI (125 of the
#: demanding scene's 500: 1.4 M samples, ample for 128 taps, at a quarter of the cost of a pass over all).
CLEANING_ROW_STEP = 4


def _cleaning_weights_from(X: np.ndarray, seglen: int, config: PCLConfig) -> np.ndarray:
    """:func:`cleaning_weights` from the raw segments' spectra ``X (B, F)`` (segments of ``seglen`` samples)."""
    K, D = config.cleaning_taps, config.cleaning_delay
    rows = np.ascontiguousarray(X[::CLEANING_ROW_STEP]) if X.shape[0] >= 2 * CLEANING_ROW_STEP else X
    # c[d] = sum_b sum_t x_b[t + d] conj(x_b[t]): the segments' autocorrelations (F >= seglen + Q: no wrap)
    power, _ = normal_sums(rows, rows, None)
    c = sfft.ifft(power)[:D + K]
    if config.pilot_hz is not None:
        # the carrier's amplitude and frequency from all rows (its refinement reads the advance between rows)
        a, omega, _ = pilot_spectral(X, config.batch_length, config.pilot_hz, config.sample_rate, length=seglen)
        d = np.arange(D + K)
        # the carrier's share in the rows read: sum_b (seglen - d) |a_b|^2 exp(j w d)
        c = c - (seglen - d) * np.sum(np.abs(a[::CLEANING_ROW_STEP] if rows is not X else a) ** 2) * np.exp(1j * omega * d)
    column = c[:K].copy()
    column[0] = c[0].real * (1.0 + config.cleaning_loading)
    return slinalg.solve_toeplitz((column, np.conj(column)), c[D:D + K])


def cleaning_weights(ref: np.ndarray, config: PCLConfig, taps: int | None = None) -> np.ndarray:
    """The reference-cleaning stage's weights: a delayed linear predictor of the reference from its own past.

    The reference antenna receives ``x[n] = d[n] + sum_p a_p d[n - tau_p]`` (the transmitted signal ``d`` and
    multipath) + noise.  For a minimum-phase channel (the direct path dominates: ``sum |a_p| < 1``) the inverse
    filter is causal, ``d[n] = x[n] - sum_{l >= 1} v_l x[n - l]``, and where ``d``'s own correlation has died out
    beyond ``D - 1`` samples the least-squares predictor of ``x[n]`` from ``x[n - D .. n - D - K_c + 1]``
    estimates it blindly (what it cannot predict is ``d[n]``): the multiple-step (delayed) linear prediction of
    Kinoshita, Delcroix, Nakatani and Miyoshi, "Suppression of late reverberation effect on speech signal using
    long-term multiple-step linear prediction", IEEE Trans. ASLP 17(4), 2009, here a short LS equaliser of the
    reference of a passive radar.  Multipath shorter than ``D`` samples (240 m at 10 MHz with ``D = 8``) only
    colours the reference spectrum and is left; an 8-VSB signal is not white (its band edges keep it correlated
    over tens of samples), so the predictor also takes a little of ``d`` (``cleaning_loading`` limits it).

    ``v = (C + delta I)^-1 c_D`` with ``C[i, j] = c[i - j]``, ``c_D[i] = c[D + i]`` and ``c[d]`` the reference's
    autocorrelation summed over the segments that :func:`batch_spectra` transforms anyway (``taps`` as there;
    every :data:`CLEANING_ROW_STEP`-th of them, spread over the CPI), ``delta = cleaning_loading * c[0]``.  The 8-VSB pilot is a perfectly predictable carrier: with
    ``config.pilot_hz`` its share (amplitude and frequency from :func:`pilot_spectral` on the same segments) is
    taken out of ``c`` first, so that the predictor spends its taps on the multipath, not on the carrier (the
    filter passes the carrier scaled, and the later stages fit it wherever it is).

    Shapes: ``ref (N,)`` -> ``(K_c,)`` complex128 (empty without cleaning).
    """
    if config.cleaning_taps < 1:
        return np.zeros(0, dtype=complex)
    K = config.eca_taps if taps is None else int(taps)
    X, _, length = _cleaning_segments(ref, config, K)
    return _cleaning_weights_from(X, length + config.cleaning_memory, config)


def cleaning_filter(weights: np.ndarray, config: PCLConfig) -> np.ndarray:
    """The cleaning filter's impulse response ``h = [1, 0 .. 0, -v_0 .. -v_{K_c - 1}]`` (``-v_i`` at lag ``D + i``).
    Shapes: ``(Q + 1,)`` complex128, ``Q = config.cleaning_memory``."""
    h = np.zeros(config.cleaning_memory + 1, dtype=complex)
    h[0] = 1.0
    h[config.cleaning_delay:] = -np.asarray(weights)
    return h


def clean_reference(ref: np.ndarray, config: PCLConfig, taps: int | None = None) -> np.ndarray:
    """The reference after the cleaning stage, ``e[n] = x[n] - sum_i v_i x[n - D - i]`` (``x[n < 0] = 0``) with
    the weights of :func:`cleaning_weights` (``taps`` as there); one full-length FFT convolution in the input's precision (the
    twin of the folded form in :func:`batch_spectra`).  Shapes: ``(N,)`` -> ``(N,)``; the input without cleaning."""
    if config.cleaning_taps < 1:
        return ref
    h = cleaning_filter(cleaning_weights(ref, config, taps), config)
    n = ref.shape[0]
    nfft = sfft.next_fast_len(n + h.size)
    w = _workers()
    out = sfft.ifft(sfft.fft(ref, nfft, workers=w) * sfft.fft(h.astype(ref.dtype), nfft), workers=w,
                    overwrite_x=True)[:n]
    return out.astype(ref.dtype, copy=False)


def pilot_spectral(R: np.ndarray, batch_length: int, pilot_hz: float, sample_rate: float, half: int = 16,
                   length: int | None = None) -> tuple[np.ndarray, float, np.ndarray]:
    """The amplitude of a carrier in every reference batch, from the batch spectra, with its frequency refined.

    With ``p[m] = exp(j w m)``, ``m < M``, and ``P`` its spectrum zero-padded to ``F`` (its energy lies within a
    few bins of the carrier: 99 % inside +-16 bins), ``a_b = sum_w R_b conj(P) / sum_w |P|^2`` over the
    ``2 half + 1`` bins around the carrier: the least-squares fit of ``a_b P`` to the batch's spectrum there
    (a carrier ``A exp(j w_t n)`` gives ``a_b ~ A exp(j w_t b M)``; restricting the fit to the carrier's bins
    keeps the rest of the band's data out of it, and costs ``B (2 half + 1)`` operations).  The nominal
    ``w_0 = 2 pi pilot_hz / f_s`` is refined once from the phase advance between batches beyond the nominal
    one, ``w = w_0 + arg(exp(-j w_0 M) sum_b a_{b+1} conj(a_b)) / M`` (unambiguous for offsets under
    ``f_s / (2M)``, 500 Hz at the defaults): a receiver's oscillator is never exactly on the nominal frequency.

    ``length``: the rows' segment length when it differs from ``batch_length`` (rows that start ``batch_length``
    apart and hold ``length`` samples, as the reference-cleaning stage's segments).

    Shapes: ``R (B, F)`` -> ``a (B,)`` complex128, ``w`` (rad/sample), ``P (F,)`` complex64.
    """
    B, F = R.shape
    m = np.arange(batch_length if length is None else int(length))

    def fit(omega: float) -> tuple[np.ndarray, np.ndarray]:
        P = sfft.fft(np.exp(1j * omega * m), F)
        k = int(round(omega * F / (2.0 * np.pi)))
        win = (k + np.arange(-half, half + 1)) % F
        Pw = P[win]
        # a_b = sum_w R_b conj(P) / sum_w |P|^2
        a = np.sum(R[:, win] * np.conj(Pw), axis=1) / np.sum(np.abs(Pw) ** 2)
        return a, P

    omega0 = 2.0 * np.pi * pilot_hz / sample_rate
    a0, _ = fit(omega0)
    # the advance beyond the nominal exp(j w_0 M) per batch
    omega = omega0 + float(np.angle(np.vdot(a0[:-1], a0[1:]) * np.exp(-1j * omega0 * batch_length))) / batch_length
    a, P = fit(omega)
    return a, omega, P.astype(np.complex64)


def remove_pilot(ref: np.ndarray, config: PCLConfig) -> np.ndarray:
    """The reference with its pilot carrier removed batch by batch (``r_b - a_b exp(j w m)``), time domain.

    The amplitudes and the refined frequency come from :func:`pilot_spectral` on the batches' own FFTs, computed
    here in the input's precision.  Shapes: ``ref (N,)`` -> ``(N,)``.  Without ``config.pilot_hz`` the input is
    returned.
    """
    if config.pilot_hz is None or not config.pilot_removal:
        return ref
    B, M = config.batches, config.batch_length
    batches = ref.reshape(B, M)
    a, omega, _ = pilot_spectral(sfft.fft(batches, config.fft_length(), axis=1, workers=_workers()), M,
                                 config.pilot_hz, config.sample_rate)
    p = np.exp(1j * omega * np.arange(M)).astype(ref.dtype)
    return (batches - a[:, None].astype(ref.dtype) * p[None, :]).reshape(-1)


def _doppler(corr: np.ndarray, config: PCLConfig) -> np.ndarray:
    """``chi(l, k) = sum_b win_b c_b[l] exp(-j 2 pi k b / B)`` for ``k = -K..K``: ``(B, L)`` -> ``(L, 2K + 1)``."""
    B, K = config.batches, config.doppler_half
    if config.doppler_window == "hamming":
        corr = corr * np.hamming(B).astype(corr.real.dtype)[:, None]
    dop = sfft.fft(corr, axis=0, workers=_workers())
    keep = np.r_[B - K:B, 0:K + 1]
    return np.ascontiguousarray(dop[keep].T)


def caf_batches(surv: np.ndarray, ref: np.ndarray, config: PCLConfig = PCLConfig()) -> CAFMap:
    """Cross-ambiguity function on the range-Doppler grid of ``config`` by the batches algorithm (reference form).

    Split the CPI into ``B`` batches of ``M`` samples; per batch, the correlation over lags
    ``l = 0..L-1`` by FFT, ``c_b[l] = sum_m s[bM + m + l] conj(r'[bM + m])`` (``r'``: the reference with its
    pilot removed, :func:`remove_pilot`); then an FFT across batches (optionally Hamming-windowed) gives
    ``chi(l, k) = sum_b c_b[l] exp(-j 2 pi k b / B)`` at ``f_D = k / CPI``, ``k = -K..K``.

    Shapes: ``surv, ref (N,)`` with ``N = config.samples``; result ``chi (L, 2K + 1)``.
    """
    n, M, B, L = config.samples, config.batch_length, config.batches, config.lags
    if surv.shape != (n,) or ref.shape != (n,):
        raise InputError(f"caf_batches: expected signals of {n} samples, got {surv.shape} and {ref.shape}")
    w = _workers()
    nfft = sfft.next_fast_len(M + L - 1)
    ref = remove_pilot(ref, config)
    # surveillance segments of length M + L - 1 starting at b M (zero-padded past the end)
    s_pad = np.concatenate([surv, np.zeros(L - 1, dtype=surv.dtype)])
    segments = np.lib.stride_tricks.sliding_window_view(s_pad, M + L - 1)[::M][:B]
    S = sfft.fft(segments, nfft, axis=1, workers=w)
    Rb = sfft.fft(ref.reshape(B, M), nfft, axis=1, workers=w)
    # c_b[l] = sum_m s[bM + m + l] conj(r[bM + m])
    corr = sfft.ifft(S * np.conj(Rb), axis=1, workers=w, overwrite_x=True)[:, :L]
    return CAFMap(_doppler(corr, config), config.range_axis, config.doppler_axis)


# -- folded form: ECA on the batch spectra, single precision -------------------------------------------------


@dataclass
class BatchSpectra:
    """The per-batch spectra of one CPI (length-``F`` FFTs, ``F = config.fft_length(taps)``).

    Shapes: ``surv (B, F)``: FFT of ``s[bM .. bM + M + L - 1)`` (zero past ``N``); ``ref (B, F)``: FFT of
    ``r[bM .. bM + M)``; ``ref_ext (B, F)`` or None: FFT of ``r[bM - K + 1 .. bM + M + L - 1)`` (zero outside
    ``[0, N)``); ``ref_tail (K - 1,)``: ``r[N - K + 1 .. N)``; ``pilot (B,)`` or None: the pilot amplitude of
    every reference batch, ``pilot_omega`` its refined frequency (rad/sample), ``pilot_spectrum (F,)`` the
    spectrum of ``exp(j pilot_omega m)``, ``m < M`` (:func:`pilot_spectral`).  :func:`caf_folded` overwrites
    ``surv`` and ``ref_ext``.
    """

    surv: np.ndarray
    ref: np.ndarray
    ref_ext: np.ndarray | None
    ref_tail: np.ndarray
    taps: int
    pilot: np.ndarray | None = None
    pilot_omega: float = 0.0
    pilot_spectrum: np.ndarray | None = None

    @property
    def nfft(self) -> int:
        return self.surv.shape[1]


def _segments(x: np.ndarray, B: int, M: int, length: int, back: int, nfft: int) -> np.ndarray:
    """``(B, nfft)`` complex64: row ``b`` holds ``x[bM - back .. bM - back + length)`` (zero outside ``[0, N)``),
    then zeros.  One strided copy: the rows entirely inside the signal come from a sliding-window view."""
    n = x.shape[0]
    out = np.empty((B, nfft), dtype=np.complex64)  # (cheaper than np.zeros: every element is written once)
    out[:, length:] = 0
    first = -(-back // M)  # the first row that starts at or after 0
    last = min(B - 1, (n - length + back) // M)  # the last row that ends at or before N
    if last >= first:
        view = np.lib.stride_tricks.sliding_window_view(x, length)[first * M - back:last * M - back + 1:M]
        out[first:last + 1, :length] = view
    for b in list(range(0, min(first, B))) + list(range(max(last + 1, first), B)):  # a row or two at the edges
        lo, hi = b * M - back, b * M - back + length
        a, z = max(lo, 0), min(hi, n)
        out[b, :length] = 0
        if a < z:
            out[b, a - lo:z - lo] = x[a:z]
    return out


def batch_spectra(surv: np.ndarray, ref: np.ndarray, config: PCLConfig = PCLConfig(), taps: int | None = None
                  ) -> BatchSpectra:
    """Stage 1 of the folded chain: the FFTs of the surveillance segments, reference batches and extended
    reference segments, and the pilot amplitudes (:func:`pilot_spectral`; see :class:`BatchSpectra`).  Single
    precision.

    With ``K`` taps the segments reach ``Ls = max(L, K)`` lags (:meth:`PCLConfig.span`).  With the cleaning stage
    (``config.cleaning_taps``) the reference is the cleaned ``e`` of :func:`clean_reference`: the raw extended
    segments reach ``Q`` samples further back, their spectra times ``H`` (the cleaning filter, shifted by ``-Q``
    so that output sample ``t`` is ``e[bM - K + 1 + t]``: exact over the segment, the circular wrap falls on
    samples no later stage reads) are the extended segments of ``e``; one inverse FFT of them gives ``e``'s
    batches for the reference spectra; the last segment's ``e[n >= N]`` (the filter's spill past the CPI, where
    the twin's reference is zero) is taken out of its spectrum.  Two more ``B x F`` transforms than without
    cleaning.
    """
    n, M, B = config.samples, config.batch_length, config.batches
    K = config.eca_taps if taps is None else int(taps)
    if surv.shape != (n,) or ref.shape != (n,):
        raise InputError(f"batch_spectra: expected signals of {n} samples, got {surv.shape} and {ref.shape}")
    if not 0 <= K <= M:
        raise InputError(f"batch_spectra: taps must be in 0..{M} (the batch length), got {K}")
    surv = np.asarray(surv, dtype=np.complex64)
    ref = np.asarray(ref, dtype=np.complex64)
    nfft = config.fft_length(K)
    Ls = config.span(K)
    w = _workers()
    # surveillance segments s[bM .. bM + M + Ls - 1) (zero past N), zero-padded to F, transformed in place
    S = _segments(surv, B, M, M + Ls - 1, 0, nfft)
    S = sfft.fft(S, axis=1, workers=w, overwrite_x=True)  # in place
    E = None
    Q = config.cleaning_memory
    if Q:
        # raw segments x[bM - back - Q .. bM - back + length) (zero outside [0, N)), transformed
        X, back, length = _cleaning_segments(ref, config, K)
        h = cleaning_filter(_cleaning_weights_from(X, length + Q, config), config)
        g = np.zeros(nfft, dtype=np.complex128)
        g[(np.arange(Q + 1) - Q) % nfft] = h  # h_l at (l - Q) mod F: output t = e[bM - back + t]
        X *= sfft.fft(g).astype(np.complex64)
        seg = np.empty_like(X)
        np.copyto(seg, X)
        seg = sfft.ifft(seg, axis=1, workers=w, overwrite_x=True)  # e[bM - back + t], t < length (exact)
        tail = seg[-1, back + M - (K - 1):back + M].copy() if K > 1 else np.zeros(0, np.complex64)
        if K > 0:
            # e[n >= N] of the last segment (t >= M + back): the twin's reference is zero there
            spill = np.zeros(nfft, dtype=np.complex64)
            stop = min(length, M + back + Q)
            spill[M + back:stop] = seg[-1, M + back:stop]
            X[-1] -= sfft.fft(spill)
            E = X
        # the reference batches e[bM .. bM + M): the window [back, back + M) of each row, moved to the start by a
        # phase ramp on its spectrum (cheaper than copying the window out)
        seg[:, :back] = 0
        seg[:, back + M:] = 0
        R = sfft.fft(seg, axis=1, workers=w, overwrite_x=True)
        if back:
            # exp(+j 2 pi k back / F), the phase reduced exactly (k back mod F) before the float
            R *= np.exp(2j * np.pi * ((np.arange(nfft) * back) % nfft) / nfft).astype(np.complex64)
        del seg
    else:
        batches = ref.reshape(B, M)
        R = np.empty((B, nfft), dtype=np.complex64)
        R[:, :M] = batches
        R[:, M:] = 0
        R = sfft.fft(R, axis=1, workers=w, overwrite_x=True)
        if K > 0:
            # extended reference segments r[bM - K + 1 .. bM + M + Ls - 1) (zero outside [0, N))
            E = _segments(ref, B, M, M + Ls + K - 2, K - 1, nfft)
            E = sfft.fft(E, axis=1, workers=w, overwrite_x=True)
        tail = ref[n - K + 1:].copy() if K > 1 else np.zeros(0, np.complex64)
    pilot, omega, P = (None, 0.0, None)
    if config.pilot_hz is not None and config.pilot_removal:
        pilot, omega, P = pilot_spectral(R, M, config.pilot_hz, config.sample_rate)
    return BatchSpectra(S, R, E, tail, K, pilot, omega, P)


def eca_weights(spec: BatchSpectra, loading: float = 1e-6, backend: str = "auto") -> np.ndarray:
    """Stage 2: the ECA weights from the batch spectra (the normal equations of :func:`eca`, exactly).

    ``b[i] = sum_n s[n + i] conj(r[n]) = sum_b IFFT(S_b conj R_b)[i]`` and the reference autocorrelation
    ``c[d] = sum_n r[n + d] conj(r[n]) = sum_b IFFT(E_b conj R_b)[K - 1 + d]``; then
    ``(toeplitz(c) + delta I) w = b`` with ``delta = loading * c[0]``, solved in double precision by the Levinson
    recursion (``scipy.linalg.solve_toeplitz``: O(K^2) and no BLAS call, whose thread pool would contend with
    the FFT and Numba threads for a 100 x 100 system).

    Shapes: ``(K,)`` complex128.
    """
    K = spec.taps
    if K < 1:
        return np.zeros(0, dtype=complex)
    bs, ae = normal_sums(spec.surv, spec.ref, spec.ref_ext, backend)
    b = sfft.ifft(bs)[:K]
    c = sfft.ifft(ae)[K - 1:2 * K - 1]
    column = c.copy()
    column[0] = c[0].real * (1.0 + loading)
    # (X^H X)[i, j] = c[i - j]: first column c, first row conj(c)
    return slinalg.solve_toeplitz((column, np.conj(column)), b)


def caf_folded(spec: BatchSpectra, weights: np.ndarray, config: PCLConfig = PCLConfig(), backend: str = "auto"
               ) -> CAFMap:
    """Stage 3: the CAF of the cancelled surveillance, computed from the batch spectra (overwrites ``spec.surv``).

    The fit ``f[n] = sum_j w_j r[n - j]`` over a surveillance segment is the circular convolution of the
    extended reference segment with ``g`` (``g[(j - K + 1) mod F] = w_j``), exact on the ``M + L - 1`` samples
    the correlation reads, so the cancelled correlation spectrum is ``(S_b - G E_b) conj(R'_b)``, with ``R'_b =
    R_b - a_b P`` the pilot-free reference batch.  One correction keeps it equal to the reference form: past the
    end of the CPI (``n >= N``) the surveillance is zero-padded, so the fit's spill ``f[N + i]``, ``i < K - 1``,
    is added back to the last batch.  Then ``c_b[l] = IFFT(...)[l]``, ``l < L``, and the Doppler FFT.
    """
    M, L = config.batch_length, config.lags
    K, F = spec.taps, spec.nfft
    w = _workers()
    G = None
    if K > 0:
        g = np.zeros(F, dtype=np.complex128)
        g[(np.arange(K) - (K - 1)) % F] = weights
        G = sfft.fft(g).astype(np.complex64)
    P = spec.pilot_spectrum
    X = clean_product(spec.surv, spec.ref, spec.ref_ext, G, None if P is None else spec.pilot.astype(np.complex64),
                      P, backend)
    if K > 1:
        # the fit past the end of the CPI, f[N + i] = sum_{j > i} w_j r[N + i - j], added back to the last batch
        # (the surveillance there is zero padding)
        # spill[i] = sum_{j > i} w_j tail[K - 1 + i - j]: the full convolution of w and the tail, from K - 1 on
        spill = np.convolve(weights, spec.ref_tail.astype(complex))[K - 1:2 * K - 2]
        e = np.zeros(F, dtype=np.complex128)
        e[M:M + K - 1] = spill
        ref_last = spec.ref[-1] if P is None else spec.ref[-1] - spec.pilot[-1] * P
        X[-1] += (sfft.fft(e) * np.conj(ref_last)).astype(np.complex64)
    corr = sfft.ifft(X, axis=1, workers=w, overwrite_x=True)[:, :L]
    return CAFMap(_doppler(corr, config), config.range_axis, config.doppler_axis)


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


def process_frame(ref: np.ndarray, surv: np.ndarray, config: PCLConfig = PCLConfig(), cancel: bool = True,
                  method: str = "folded", backend: str = "auto") -> tuple[CAFMap, Candidates, np.ndarray]:
    """Reference cleaning (with ``config.cleaning_taps``) -> ECA (optional) -> CAF -> CFAR candidates for one CPI.

    ``method="folded"``: :func:`batch_spectra`, :func:`eca_weights`, :func:`caf_folded` (single precision);
    ``"reference"``: :func:`eca` + :func:`caf_batches` in the input's precision (the twin).
    """
    taps = config.eca_taps if cancel else 0
    if method == "folded":
        spec = batch_spectra(surv, ref, config, taps)
        weights = eca_weights(spec, config.eca_loading, backend)
        caf = caf_folded(spec, weights, config, backend)
    elif method == "reference":
        ref = clean_reference(ref, config, taps)
        if taps:
            surv, _ = eca(surv, ref, taps, config.eca_loading)
        caf = caf_batches(surv, ref, config)
    else:
        raise InputError(f"process_frame: method must be 'folded' or 'reference', got {method!r}")
    cands, mask = cfar_candidates(caf, config)
    return caf, cands, mask


def _label(c: Candidates, true_rr: np.ndarray, config: PCLConfig) -> int:
    """Row of the candidate within 1.5 range and 1.5 Doppler bins of the true cell (nearest), or -1."""
    f_true = range_rate_to_doppler(true_rr[1], config.wavelength)
    dr = np.abs(c.range_m - true_rr[0]) / config.range_bin
    dd = np.abs(c.doppler_hz - f_true) / config.doppler_bin
    near = (dr <= 1.5) & (dd <= 1.5)
    return int(np.argmin(np.where(near, dr * dr + dd * dd, np.inf))) if near.any() else -1


def _as_scans(frames, truth_rr: np.ndarray, times: np.ndarray, config: PCLConfig) -> Scans:
    B, T, _ = truth_rr.shape
    M = max([len(c.range_m) for row in frames for c in row], default=0)
    z = np.zeros((B, T, M, 2))
    valid = np.zeros((B, T, M), dtype=bool)
    snr = np.full((B, T, M), np.nan)
    dop = np.full((B, T, M), np.nan)
    origin = np.full((B, T, M), CLUTTER, dtype=int)
    for b in range(B):
        for t in range(T):
            c = frames[b][t]
            m = len(c.range_m)
            z[b, t, :m, 0], z[b, t, :m, 1] = c.range_m, c.range_rate
            valid[b, t, :m] = True
            snr[b, t, :m], dop[b, t, :m] = c.strength_db, c.doppler_hz
            j = _label(c, truth_rr[b, t], config)
            if j >= 0:
                origin[b, t, j] = 0
    return Scans(z, valid, np.asarray(times, dtype=float), snr=snr, doppler=dop, origin=origin)


def simulate_scans_multi(truth_rr: np.ndarray, times: np.ndarray, rng: np.random.Generator, configs,
                         scene: SignalScene = BENIGN_SCENE) -> list[Scans]:
    """Signal-level candidates of the same frames processed by several receivers (``configs``, one
    :class:`Scans` each): every frame is synthesised once (with ``configs[0]``'s grid) and processed by each.

    Same output as the detection-level sensor: ``z = [R, Rdot]``, ``doppler`` (Hz), ``snr`` (strength, dB).
    The candidate nearest the true target cell, within 1.5 range and 1.5 Doppler bins, is labelled as the
    target (origin 0); every other candidate is clutter.
    """
    truth_rr = np.asarray(truth_rr, dtype=float)
    if truth_rr.ndim != 3 or truth_rr.shape[-1] != 2:
        raise InputError(f"simulate_scans expects truth (B, T, 2), got {truth_rr.shape}")
    configs = list(configs)
    B, T, _ = truth_rr.shape
    frames = [[[None] * T for _ in range(B)] for _ in configs]
    for b in range(B):
        for t in range(T):  # one frame is a whole-array FFT computation of N samples
            ref, surv = frame_signals(truth_rr[b, t][None], rng, configs[0], scene)
            for i, cfg in enumerate(configs):
                frames[i][b][t] = process_frame(ref, surv, cfg)[1]
    return [_as_scans(f, truth_rr, times, cfg) for f, cfg in zip(frames, configs)]


def simulate_scans(truth_rr: np.ndarray, times: np.ndarray, rng: np.random.Generator,
                   config: PCLConfig = PCLConfig(), scene: SignalScene = BENIGN_SCENE) -> Scans:
    """Signal-level candidates for target tracks ``truth_rr (B, T, 2)`` of ``[R, Rdot]``: a :class:`Scans`
    (see :func:`simulate_scans_multi`)."""
    return simulate_scans_multi(truth_rr, times, rng, [config], scene)[0]
