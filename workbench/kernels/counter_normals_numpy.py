"""Counter-based standard normals, the NumPy twin and the shared constants: the normals of row ``b`` of stream ``key`` are a pure function of ``(key, b)``.

A kernel can therefore compute the normals it needs where it needs them, in parallel and vectorised,
and every backend (this module's NumPy twin, the Numba kernels) gives the same numbers bit for bit.  The key
comes from the caller's ``np.random.Generator`` (one 64-bit draw per use), so every number still
flows from the explicit seed.  This docstring is the generator's specification.

Row ``b`` holds ``count`` normals made in ``P = ceil(count / 2)`` pairs; pair ``g = b P + j`` is the
Box-Muller transform of ONE hashed counter, in float32 arithmetic (every operation below rounds to float32;
every constant is a float32)::

    w    = splitmix64(key + (g + 1) GAMMA)          (mod 2^64)
    k    = w >> 41                                  (23 bits)
    p    = (1 + k 2^-23) - (1 - 2^-24)  = (2 k + 1) 2^-24,  uniform in (0, 1), exact in float32
    rad  = sqrt(-2 log p)
    quadrant = (w >> 39) & 3,   i = (w >> 16) & (2^23 - 1),   u = (1 + i 2^-23) - (1 - 2^-24) = (2 i + 1) 2^-24
    th   = (quadrant + u) pi / 2
    normal 2j = rad cos th,   normal 2j + 1 = rad sin th       (the float32 products, stored as float64: exact)

(``splitmix64`` is SplitMix64's output function, ``GAMMA = 2^64 / golden ratio``.)  ``1 + k 2^-23`` is the
float32 whose mantissa bits are ``k`` (no integer-to-float conversion), and both subtractions are exact
(Sterbenz).  Every ``p`` and ``u`` lies on the grid ``(2 i + 1) 2^-24``; the smallest ``p`` is ``2^-24``, so
``|normal| <= sqrt(48 ln 2) = 5.77``: the tail this cuts is ``P(rad > 5.77) = exp(-5.77^2 / 2) = 2^-24`` per pair
(a standard normal is beyond 5.77 in magnitude with probability 8e-9).

Everything is written with selects only, so a loop over ``j`` vectorises (float32 lanes):

- ``log x`` (:func:`log_poly`) by the exponent bits, ``x = m 2^e`` with ``m`` in ``[sqrt(1/2), sqrt(2))``, then
  fdlibm's form of ``log m = log(1 + f) = 2 atanh(s)``, ``f = m - 1`` (exact), ``s = f / (2 + f)``::

      log x = e LN2_HI - ((h - (s (h + R) + e LN2_LO)) - f),   h = f^2 / 2,   z = s^2,
      R = z (2/3 + z (2/5 + z (2/7 + z 2/9)))

  (``e`` as ``(2^23 + exponent bits) - (2^23 + 127)``, exact; ``e LN2_HI`` exact for ``|e| < 2^7``).  Its error
  against float64 ``math.log`` of the same float32 input is at most 0.86 float32 ulps (0.26 on average) over
  the 2^23 values of ``p`` (every one checked by the tests).
- ``cos`` and ``sin`` (:func:`sincos_poly`) of ``th = (quadrant + u) pi / 2`` by Taylor polynomials in ``t``, the
  fraction itself, ``sin(t pi / 2) = t S(t^2)`` (5 terms, to ``t^9``) and ``cos(t pi / 2) = C(t^2)`` (6 terms, to
  ``t^10``), on ``t`` in ``(0, 1/2]``: ``u > 1/2`` uses the complement ``t = 1 - u`` (exact) and swaps sine and
  cosine, then the quadrant rotates and negates them.  The truncation is below 0.03 ulp; the error against
  float64 ``math.cos`` / ``math.sin`` of the exact angle is at most 1.74 float32 ulps over the 2^23 values of
  ``u`` in each of the four quadrants (the tests check every ``u``, each in a random quadrant).

No fused multiply-add and no reassociation anywhere (NumPy has none; Numba contracts nothing without fastmath):
the Numba twin does these float32 operations in this order and gives the same bits.  A library ``log`` or ``sin``
per element does not vectorise; on one core of a 2-core AMD EPYC Zen 1 (AVX2 on 128-bit units) the Numba twin
takes 3.6 ns a normal (see :mod:`.counter_normals_numba`), this twin about 60 ns.

(Until this float32 generator a pair took two hash words and a float64 Box-Muller with 53-bit uniforms, 7.0 ns a
normal measured beside it there, ``|normal| <= 8.6``: the numbers of every run that uses counter normals, the
CRPF's, changed with it, statistically equivalent.)

Shapes: :func:`counter_normals_numpy` ``(key, rows, count) -> (rows, count)`` float64.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["counter_normals_numpy", "draw_key", "log_poly", "sincos_poly", "pair_words", "unit24", "GAMMA", "MIX1",
           "MIX2", "ONE_BITS", "BELOW_ONE", "EXP_OFFSET", "LN2_HI", "LN2_LO", "SQRT2", "LOG_SERIES", "SIN_SERIES",
           "COS_SERIES", "HALF", "ONE", "TWO", "MINUS_TWO"]

GAMMA = 0x9E3779B97F4A7C15  # 2^64 / golden ratio, SplitMix64's increment
MIX1 = 0xBF58476D1CE4E5B9
MIX2 = 0x94D049BB133111EB
f32 = np.float32
#: the bits of float32 1.0: ``k | ONE_BITS`` is ``1 + k 2^-23`` for ``k < 2^23``
ONE_BITS = 0x3F800000
BELOW_ONE = f32(1.0 - 2.0 ** -24)  # exact
EXP_OFFSET = f32(2.0 ** 23 + 127.0)  # exact
#: ln 2 split (fdlibm's float32 pair) so that e LN2_HI is exact for |e| < 2^7
LN2_HI = np.array(0x3F317180, dtype=np.uint32).view(np.float32)[()]
LN2_LO = np.array(0x3717F7D1, dtype=np.uint32).view(np.float32)[()]
SQRT2 = f32(math.sqrt(2.0))
HALF, ONE, TWO, MINUS_TWO = f32(0.5), f32(1.0), f32(2.0), f32(-2.0)
#: 2 / (2k + 3), k = 0..3: log(1 + f) = f - h + s (h + R),  R = z sum_k c_k z^k,  z = s^2 <= 0.0295
LOG_SERIES = tuple(f32(2.0 / (2 * k + 3)) for k in range(4))
#: sin(t pi / 2) / t and cos(t pi / 2) in powers of t^2 (Taylor, to t^9 and t^10), on t in (0, 1/2]
SIN_SERIES = tuple(f32((-1) ** k * (0.5 * math.pi) ** (2 * k + 1) / math.factorial(2 * k + 1)) for k in range(5))
COS_SERIES = tuple(f32((-1) ** k * (0.5 * math.pi) ** (2 * k) / math.factorial(2 * k)) for k in range(6))


def draw_key(rng: np.random.Generator) -> int:
    """A stream key from the caller's generator (one 64-bit draw)."""
    return int(rng.integers(0, 2 ** 64, dtype=np.uint64))


def _horner(coeffs, x):
    out = coeffs[-1]
    for c in coeffs[-2::-1]:
        out = out * x + c
    return out


def _splitmix(key: int, counters: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        s = np.uint64(key) + counters.astype(np.uint64) * np.uint64(GAMMA)
        s = (s ^ (s >> np.uint64(30))) * np.uint64(MIX1)
        s = (s ^ (s >> np.uint64(27))) * np.uint64(MIX2)
    return s ^ (s >> np.uint64(31))


def pair_words(key: int, g: np.ndarray) -> np.ndarray:
    """The hash word ``w = splitmix64(key + (g + 1) GAMMA)`` of each pair ``g`` (uint64)."""
    return _splitmix(key, np.asarray(g, dtype=np.uint64) + np.uint64(1))


def unit24(bits23: np.ndarray) -> np.ndarray:
    """``(2 i + 1) 2^-24`` as float32 for 23-bit integers ``i``, exactly: ``(1 + i 2^-23) - (1 - 2^-24)``."""
    one_plus = (np.asarray(bits23).astype(np.uint32) | np.uint32(ONE_BITS)).view(np.float32)
    return one_plus - BELOW_ONE


def log_poly(x: np.ndarray) -> np.ndarray:
    """``log x`` in float32 for positive normal float32 ``x``, as the module docstring writes it (<= 0.86 ulp over
    the generator's ``p``, ``[2^-24, 1)``)."""
    x = np.asarray(x, dtype=np.float32)
    bits = x.view(np.uint32)
    # x = m 2^e, m in [1, 2); the exponent as a float32 without an integer conversion
    e = ((bits >> np.uint32(23)) | np.uint32(0x4B000000)).view(np.float32) - EXP_OFFSET
    m = ((bits & np.uint32(0x007FFFFF)) | np.uint32(ONE_BITS)).view(np.float32)
    big = m > SQRT2
    m = np.where(big, HALF * m, m)  # m in [sqrt(1/2), sqrt(2))
    e = e + np.where(big, ONE, f32(0.0))
    f = m - ONE
    s = f / (TWO + f)
    z = s * s
    r = z * _horner(LOG_SERIES, z)
    h = HALF * f * f
    # log(1 + f) = f - h + s (h + R), summed small terms first
    return e * LN2_HI - ((h - (s * (h + r) + e * LN2_LO)) - f)


def sincos_poly(quadrant: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(cos th, sin th)`` in float32 of ``th = (quadrant + u) pi / 2``, ``u`` float32 in (0, 1), by the Taylor
    polynomials in ``t = u`` or ``1 - u`` on (0, 1/2] (the module docstring; <= 1.74 ulp)."""
    u = np.asarray(u, dtype=np.float32)
    quadrant = np.asarray(quadrant)
    flip = u > HALF
    t = np.where(flip, ONE - u, u)  # in (0, 1/2]
    z = t * t
    st, ct = t * _horner(SIN_SERIES, z), _horner(COS_SERIES, z)
    s_psi, c_psi = np.where(flip, ct, st), np.where(flip, st, ct)  # psi = u pi / 2
    odd = (quadrant & 1) == 1
    cos, sin = np.where(odd, -s_psi, c_psi), np.where(odd, c_psi, s_psi)
    neg = quadrant >= 2
    return np.where(neg, -cos, cos), np.where(neg, -sin, sin)


def box_muller_words(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two normals (float32) of each pair with hash word ``w``: ``(rad cos th, rad sin th)``."""
    p = unit24(w >> np.uint64(41))
    rad = np.sqrt(MINUS_TWO * log_poly(p))
    quadrant = ((w >> np.uint64(39)) & np.uint64(3)).astype(np.int64)
    cos, sin = sincos_poly(quadrant, unit24((w >> np.uint64(16)) & np.uint64(0x7FFFFF)))
    return rad * cos, rad * sin


def counter_normals_numpy(key: int, rows: int, count: int) -> np.ndarray:
    """The NumPy twin of :func:`counter_normals`, written from the formulas in the module docstring."""
    pairs = (count + 1) // 2
    n0, n1 = box_muller_words(pair_words(key, np.arange(rows * pairs, dtype=np.uint64)))
    out = np.empty((rows, 2 * pairs))
    out[:, 0::2] = n0.astype(np.float64).reshape(rows, pairs)
    out[:, 1::2] = n1.astype(np.float64).reshape(rows, pairs)
    return out[:, :count]
