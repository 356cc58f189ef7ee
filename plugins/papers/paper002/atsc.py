"""An ATSC A/53 8-VSB broadcast as the illuminator: symbols, segment and field syncs, pilot, VSB spectrum.

The paper's illuminator is the DTV channel of KBS1 at 701 MHz from Hwangryeongsan (Busan).  Korean terrestrial
HD television is ATSC A/53 8-VSB, which fits the paper's numbers: a 6 MHz channel (698-704 MHz) centred on
701 MHz.  (The UHD service uses ATSC 3.0, an OFDM waveform; the paper gives no hint of it.)  The structure a
passive radar sees, as A/53 defines it:

- symbols at ``R_s = 4.5 MHz / 286 * 684 = 10.762238 MHz``, eight levels ``{-7, -5, ..., 7}`` (trellis-coded
  data, i.i.d. uniform here);
- segments of 832 symbols, each starting with the segment sync ``+5 -5 -5 +5`` (every 77.3 us, i.e. a
  correlation repeat every 23.2 km of bistatic range: outside a 0-3 km map);
- fields of 313 segments; the first is the field sync: segment sync, PN511, PN63, PN63 (inverted on every
  other field), PN63, then 24 + 92 + 12 mode / reserved / precode symbols (a fixed +-5 pattern here), binary
  symbols at +-5;
- the pilot: +1.25 added to every symbol, a carrier at the lower edge of the data band,
  ``R_s / 4 = 2.690559 MHz`` below the channel centre, 11.3 dB below the data power;
- vestigial sideband: the real symbol stream filtered to ``u = f - f_pilot`` in ``[-beta, R_s / 2 + beta]``
  with root-raised-cosine (Nyquist) edges of half-width ``beta = 0.1152 R_s / 4 = 0.31 MHz`` (6 MHz in all).

The spectrum is built on the FFT grid of the simulation (``f_s / total``): the symbol stream's FFT has
``n_sym`` bins at the same spacing when ``n_sym / total = R_s' / f_s``.  Both lengths are chosen 7-smooth
(fast FFTs), so the simulated symbol rate ``R_s'`` differs from A/53's by the reported ``rate_error`` (about
1e-5); the receiver does not rely on the exact value (it estimates the pilot's frequency, see
:func:`workbench_papers.paper002.signal.pilot_spectral`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy import fft as sfft

__all__ = ["SYMBOL_RATE", "SEGMENT", "FIELD_SEGMENTS", "SEGMENT_SYNC", "PILOT_LEVEL", "ROLLOFF", "pilot_offset_hz",
           "pn_sequence", "PN511", "PN63", "field_sync_segment", "symbol_stream", "vsb_lengths", "vsb_spectrum"]

#: A/53 symbol rate (Hz): 4.5 MHz / 286 * 684.
SYMBOL_RATE = 4.5e6 / 286.0 * 684.0
#: Symbols per data segment.
SEGMENT = 832
#: Segments per field (the first is the field sync).
FIELD_SEGMENTS = 313
#: The segment sync, the first four symbols of every segment.
SEGMENT_SYNC = (5.0, -5.0, -5.0, 5.0)
#: The pilot: a DC level added to every symbol.
PILOT_LEVEL = 1.25
#: Excess bandwidth of the Nyquist edges relative to ``R_s / 4`` (0.31 MHz of 2.69 MHz).
ROLLOFF = 0.1152
LEVELS = np.array([-7.0, -5.0, -3.0, -1.0, 1.0, 3.0, 5.0, 7.0], dtype=np.float32)


def pilot_offset_hz(symbol_rate: float = SYMBOL_RATE) -> float:
    """The pilot's frequency relative to the channel centre: ``-R_s / 4`` (-2.690559 MHz for A/53)."""
    return -symbol_rate / 4.0


def pn_sequence(degree: int, taps: tuple[int, ...], length: int | None = None) -> np.ndarray:
    """A maximal-length sequence of a Fibonacci shift register, as +-1.

    The feedback is the XOR of the register cells named by ``taps`` (the exponents of the generator
    polynomial other than ``x^0``); the register starts at ``1 0 ... 0``.  A primitive polynomial gives the
    period ``2^degree - 1``.

    Returns ``(length,)`` float32 in ``{-1, +1}`` (``length`` defaults to one period).
    """
    length = (1 << degree) - 1 if length is None else int(length)
    reg = [1] + [0] * (degree - 1)
    out = np.empty(length, dtype=np.float32)
    for i in range(length):  # a few hundred steps, once per process
        out[i] = 1.0 - 2.0 * reg[-1]
        fb = 0
        for t in taps:
            fb ^= reg[t - 1]
        reg = [fb] + reg[:-1]
    return out


#: A/53's PN511 (generator ``x^9 + x^7 + x^6 + x^4 + x^3 + x + 1``) and PN63 (``x^6 + x + 1``), as +-1.
PN511 = pn_sequence(9, (9, 7, 6, 4, 3, 1))
PN63 = pn_sequence(6, (6, 1))


def field_sync_segment(odd: bool) -> np.ndarray:
    """The 832 symbols of a field-sync segment (before the pilot): sync, PN511, PN63 x 3, 128 fixed symbols.

    The middle PN63 is inverted on odd fields.  Binary symbols are +-5.  Shapes: ``(832,)`` float32.
    """
    rest = pn_sequence(7, (7, 1), 24 + 92 + 12)  # mode / reserved / precode: a fixed +-1 pattern here
    parts = [np.asarray(SEGMENT_SYNC, dtype=np.float32) / 5.0, PN511, PN63, -PN63 if odd else PN63, PN63, rest]
    seg = 5.0 * np.concatenate(parts)
    assert seg.size == SEGMENT
    return seg.astype(np.float32)


_FIELD_SYNC = (field_sync_segment(False), field_sync_segment(True))


def symbol_stream(n: int, rng: np.random.Generator, start: int | None = None) -> np.ndarray:
    """``n`` consecutive 8-VSB symbols with syncs and pilot, starting at a random point of the two-field frame.

    Data symbols are uniform on the eight levels; the first four symbols of each segment are the segment
    sync; the first segment of each field is the field sync; the pilot level 1.25 is added to every symbol.
    Shapes: ``(n,)`` float32.
    """
    frame = 2 * FIELD_SEGMENTS * SEGMENT
    start = int(rng.integers(0, frame)) if start is None else int(start) % frame
    x = LEVELS[rng.integers(0, 8, n)]
    # segment syncs: absolute symbol index (start + i) with (start + i) % 832 == k for k < 4
    for k, level in enumerate(SEGMENT_SYNC):
        x[(k - start) % SEGMENT::SEGMENT] = level
    # field syncs: the segments whose index is a multiple of 313 (field parity = which of the two fields)
    first_seg = start // SEGMENT
    last_seg = (start + n - 1) // SEGMENT
    for seg in range(-(-first_seg // FIELD_SEGMENTS) * FIELD_SEGMENTS, last_seg + 1, FIELD_SEGMENTS):
        sync = _FIELD_SYNC[(seg // FIELD_SEGMENTS) % 2]
        a = seg * SEGMENT - start  # position of the segment's first symbol in x (may be < 0)
        lo, hi = max(a, 0), min(a + SEGMENT, n)
        x[lo:hi] = sync[lo - a:hi - a]
    x += np.float32(PILOT_LEVEL)
    return x


def _smooth(lo: int, hi: int) -> np.ndarray:
    """Sorted 7-smooth integers in ``[lo, hi]`` (lengths pocketfft transforms fastest)."""
    vals = []
    p2 = 1
    while p2 <= hi:
        p3 = p2
        while p3 <= hi:
            p5 = p3
            while p5 <= hi:
                p7 = p5
                while p7 <= hi:
                    if p7 >= lo:
                        vals.append(p7)
                    p7 *= 7
                p5 *= 5
            p3 *= 3
        p2 *= 2
    return np.array(sorted(vals), dtype=np.int64)


@lru_cache(maxsize=16)
def vsb_lengths(min_total: int, sample_rate: float, symbol_rate: float = SYMBOL_RATE) -> tuple[int, int, float]:
    """FFT lengths ``(total, n_sym)`` with ``n_sym / total ~ R_s / f_s``: both 7-smooth, ``n_sym % 4 == 0``.

    ``total >= min_total`` (within 6 % of it); the pair whose ratio is closest to ``R_s / f_s`` wins.
    Returns ``total, n_sym`` and the simulated symbol rate's relative error ``R_s' / R_s - 1``.
    """
    ratio = symbol_rate / sample_rate
    totals = _smooth(min_total, int(np.ceil(1.06 * min_total)))
    quarters = _smooth(int(totals[0] * ratio / 4) - 1, int(np.ceil(totals[-1] * ratio / 4)) + 1)
    best = None
    for t in totals:
        j = np.searchsorted(quarters, t * ratio / 4.0)
        for q in quarters[max(j - 1, 0):j + 1]:
            err = 4.0 * q / (t * ratio) - 1.0
            if best is None or abs(err) < abs(best[2]) - 1e-12:
                best = (int(t), int(4 * q), float(err))
    return best


@lru_cache(maxsize=4)
def _vsb_filter(total: int, n_sym: int, sample_rate: float) -> tuple[int, np.ndarray]:
    """The VSB filter amplitude on the occupied output bins: ``(k_lo, H (K,))`` with bins ``k_lo .. k_lo + K - 1``
    (signed), ``u = f - f_pilot``, ``R_s' = n_sym f_s / total``.  See :func:`vsb_spectrum`."""
    symbol_rate_sim = n_sym * sample_rate / total
    df = sample_rate / total
    beta_bins = int(np.ceil(ROLLOFF * symbol_rate_sim / 4.0 / df))
    u_bin = np.arange(-beta_bins, n_sym // 2 + beta_bins + 1)
    u = u_bin * df
    beta = ROLLOFF * symbol_rate_sim / 4.0
    low = np.clip(u / beta, -1.0, 1.0)
    high = np.clip((u - symbol_rate_sim / 2.0) / beta, -1.0, 1.0)
    h2 = 0.5 * (1.0 + np.sin(0.5 * np.pi * low)) * 0.5 * (1.0 - np.sin(0.5 * np.pi * high))
    return int(u_bin[0] - n_sym // 4), np.sqrt(h2).astype(np.float32)


def vsb_spectrum(total: int, sample_rate: float, rng: np.random.Generator, n_sym: int) -> np.ndarray:
    """Spectrum (length-``total`` FFT, complex64, unit mean time-domain power) of one 8-VSB channel.

    The channel is centred on 0 Hz.  ``n_sym`` symbols at the simulated rate ``R_s' = n_sym f_s / total`` (from
    :func:`vsb_lengths`) are transformed once; output bin ``k`` (frequency ``k f_s / total``) takes the symbol
    spectrum at ``u = f - f_pilot``, i.e. symbol bin ``k + n_sym / 4`` (real symbols: ``X(-u) = conj X(u)``,
    period ``n_sym``), times the VSB filter ``H(u)``:

        ``H(u)^2 = 1/2 (1 + sin(pi u / (2 beta)))``  for ``|u| <= beta``            (Nyquist edge at the pilot)
        ``H(u)^2 = 1``                                 for ``beta < u < R_s'/2 - beta``
        ``H(u)^2 = 1/2 (1 - sin(pi (u - R_s'/2) / (2 beta)))``  for ``|u - R_s'/2| <= beta``

    with ``beta = ROLLOFF R_s' / 4``, zero elsewhere.
    """
    if n_sym % 4:
        raise ValueError("n_sym must be a multiple of 4 (the pilot sits at symbol bin n_sym / 4)")
    k_lo, h = _vsb_filter(total, n_sym, sample_rate)
    beta_bins = -(k_lo + n_sym // 4)
    X = sfft.rfft(symbol_stream(n_sym, rng), workers=1)  # symbol bins 0 .. n_sym / 2
    half = n_sym // 2
    # symbol bins -beta .. n_sym/2 + beta: X(-u) = conj X(u) below 0, X(u) = conj X(n_sym - u) above n_sym / 2
    occupied = np.concatenate([np.conj(X[beta_bins:0:-1]), X, np.conj(X[half - 1:half - 1 - beta_bins:-1])])
    occupied *= h
    spec = np.zeros(total, dtype=np.complex64)
    # signed output bins k_lo .. k_lo + size - 1: the negative ones sit at the end of the FFT order
    spec[total + k_lo:] = occupied[:-k_lo]
    spec[:occupied.size + k_lo] = occupied[-k_lo:]
    # unit mean power: sum |Y_k|^2 = total^2 (numpy's unnormalised FFT)
    spec *= np.float32(total / np.sqrt(float(np.vdot(occupied, occupied).real)))
    return spec
