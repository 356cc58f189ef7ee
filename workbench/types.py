"""Batch-first records that flow between sensors, clutter plugins, filters and metrics.

Every numerical field carries a leading batch axis ``B`` (Monte Carlo runs, or live tracks in a
multi-target tracker).  Records are frozen dataclasses that validate their shapes once, when they
are built, so a malformed array is reported where it enters rather than deep inside a filter.

Shapes
------
- ``Gaussian``: ``mean (B, n)``, ``cov (B, n, n)``
- ``Particles``: ``particles (B, N, n)``, ``log_weights (B, N)`` (normalised in the log domain)
- ``Scan``: one scan, measurements padded to ``(B, M, m)`` with a ``valid (B, M)`` mask
- ``Scans``: a whole scenario's scans, ``(B, T, M, m)`` with ``valid (B, T, M)``
- ``Truth``: ``states (B, T, n)`` at ``times (T,)``
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

__all__ = [
    "CLUTTER",
    "Gaussian",
    "Particles",
    "Scan",
    "Scans",
    "Truth",
    "InputError",
    "check_covariance",
    "check_size",
    "real_scalar",
]

#: Origin label of a detection that came from clutter (metrics only; filters never see it).
CLUTTER = -1


class InputError(ValueError):
    """Bad input handed to the workbench: the message names the record, the field and the problem."""


def _array(name: str, value, ndim: int, dtype=float) -> np.ndarray:
    arr = _as_array(name, value, dtype)
    if arr.ndim != ndim:
        raise InputError(f"{name} must have {ndim} dimensions, got shape {arr.shape}")
    return arr


def _as_array(name: str, value, dtype=float) -> np.ndarray:
    """``value`` as an array of ``dtype`` (``float``, ``int`` or ``bool``), refusing what that dtype cannot hold
    with a named :class:`InputError`: complex numbers (the imaginary part would be lost), ``datetime64`` /
    ``timedelta64`` (no unit is stated: times are seconds as floats), text and objects that are not plain numbers
    (``"False"`` would read as true), integers that are not whole numbers, masks that are not 0/1."""
    if isinstance(value, np.ndarray) and value.dtype == np.dtype(dtype):
        return value
    try:
        raw = np.asarray(value)
    except (ValueError, TypeError) as exc:
        raise InputError(f"{name}: cannot read the value as an array of numbers ({exc})") from None
    kind = raw.dtype.kind
    if kind == "O":
        flat = raw.ravel()
        odd = next((v for v in flat if isinstance(v, (complex, np.complexfloating))
                    or not isinstance(v, (int, float, bool, np.integer, np.floating, np.bool_))), _NONE)
        if odd is not _NONE:
            raise InputError(f"{name} holds {type(odd).__name__} {odd!r} among its values; it takes real numbers")
        raw = raw.astype(float)
        kind = "f"
    if kind == "c":
        raise InputError(f"{name} holds complex numbers (dtype {raw.dtype}); it takes real numbers: pass the real "
                         f"and imaginary parts (or magnitude and phase) as separate components")
    if kind in "Mm":
        raise InputError(f"{name} holds {raw.dtype} values, whose unit the workbench does not guess; times and "
                         f"durations are seconds as floats: convert first, e.g. (t - t[0]) / np.timedelta64(1, 's')")
    if kind in "USV":
        raise InputError(f"{name} holds text or raw records (dtype {raw.dtype}), not numbers")
    if dtype is bool:
        if kind != "b":
            with np.errstate(invalid="ignore"):
                if not np.all((raw == 0) | (raw == 1)):
                    bad = raw.ravel()[~((raw.ravel() == 0) | (raw.ravel() == 1))][0]
                    raise InputError(f"{name} is a mask: it takes booleans (or 0 and 1), got {bad.item()!r} "
                                     f"(dtype {raw.dtype})")
        return raw.astype(bool)
    if dtype is int and kind == "f":
        with np.errstate(invalid="ignore"):
            whole = np.isfinite(raw) & (raw == np.round(raw))
        if not np.all(whole):
            bad = raw.ravel()[~whole.ravel()][0]
            raise InputError(f"{name} takes whole numbers, got {bad.item()!r}")
    return raw.astype(dtype)


_NONE = object()


def real_scalar(name: str, value) -> float:
    """A real number (not complex, text, a date or a boolean) as a float; :class:`InputError` naming ``name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        if isinstance(value, np.ndarray) and value.ndim == 0:
            return real_scalar(name, value[()])
        hint = (" (times are seconds as floats: convert first, e.g. (t - t0) / np.timedelta64(1, 's'))"
                if isinstance(value, (np.datetime64, np.timedelta64)) else "")
        raise InputError(f"{name} must be a real number, got {type(value).__name__} {value!r}{hint}")
    return float(value)


def memory_limit() -> float:
    """Bytes of physical memory of this machine (8 GiB where the system does not say)."""
    import os

    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not a POSIX system
        return 8.0 * 2 ** 30


def check_size(name: str, value, item_bytes: float = 8.0, minimum: int = 1, share: float = 0.5) -> int:
    """``value`` as a count (a batch, a number of steps, a dimension) that some call allocates ``item_bytes`` per
    unit of: a whole number ``>= minimum`` whose allocation fits in ``share`` of the machine's memory;
    :class:`InputError` naming ``name`` otherwise (instead of NumPy's raw ``ValueError`` or ``MemoryError``)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer, float, np.floating)) or (
            isinstance(value, (float, np.floating)) and not float(value).is_integer()):
        raise InputError(f"{name} must be a whole number >= {minimum}, got {value!r}")
    count = int(value)
    if count < minimum:
        raise InputError(f"{name} must be >= {minimum}, got {count}")
    limit = share * memory_limit()
    if count * float(item_bytes) > limit:
        raise InputError(f"{name} = {count} needs about {count * float(item_bytes) / 2**30:.3g} GiB; this machine "
                         f"allows {limit / 2**30:.3g} GiB ({share:.0%} of its memory): ask for less")
    return count


def _require_finite(name: str, arr: np.ndarray) -> None:
    if not np.isfinite(arr).all():
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(f"{name} holds a non-finite value (NaN or inf) at index {tuple(int(i) for i in bad)}")


#: Relative tolerance of the covariance checks: ``|P - P^T| <= SYMMETRY_TOL * scale`` and every eigenvalue
#: ``>= -PSD_TOL * scale``, ``scale`` the largest diagonal entry of ``P`` (at least 1e-300).
SYMMETRY_TOL = 1e-8
PSD_TOL = 1e-8
#: Log-weights are normalised when ``|logsumexp(log_weights)| <= WEIGHT_TOL`` per item.
WEIGHT_TOL = 1e-6


def check_covariance(name: str, cov: np.ndarray) -> None:
    """Symmetric and positive semi-definite to :data:`SYMMETRY_TOL` / :data:`PSD_TOL` (relative to the largest
    diagonal entry of each matrix); :class:`InputError` naming the first bad item otherwise.  ``cov (..., n, n)``."""
    if cov.size == 0:
        return
    scale = np.maximum(np.abs(np.diagonal(cov, axis1=-2, axis2=-1)).max(axis=-1), 1e-300)
    asym = np.abs(cov - np.swapaxes(cov, -1, -2)).max(axis=(-2, -1))
    bad = asym > SYMMETRY_TOL * scale
    if np.any(bad):
        item = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"{name} is not symmetric at item {item} (|P - P^T| = {asym[item]:.3g})")
    low = np.linalg.eigvalsh(0.5 * (cov + np.swapaxes(cov, -1, -2)))[..., 0]
    bad = low < -PSD_TOL * scale
    if np.any(bad):
        item = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"{name} is not positive semi-definite at item {item} (smallest eigenvalue "
                         f"{low[item]:.3g})")


@dataclass(frozen=True)
class Gaussian:
    """A batch of Gaussian beliefs ``N(mean[b], cov[b])``.

    Built with ``Gaussian(mean, cov)`` the record checks its shapes, that every number is finite and that every
    covariance is symmetric and positive semi-definite (:func:`check_covariance`).  Filter code whose algebra
    guarantees symmetry and semi-definiteness (a Joseph-form update, a moment of weighted particles) may build its
    results with :meth:`trusted`, which checks shapes and finiteness only; the filter test kit checks every
    filter's covariances.

    Shapes
    ------
    mean : (B, n)
    cov : (B, n, n)
    """

    mean: np.ndarray
    cov: np.ndarray

    #: The batch-first fields: how a tracker takes and joins batch items (:func:`workbench.specs.take_batch`).
    batch_fields = ("mean", "cov")

    def __post_init__(self) -> None:
        mean, cov = self._checked(self.mean, self.cov)
        check_covariance("Gaussian.cov", cov)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)

    @staticmethod
    def _checked(mean, cov) -> tuple[np.ndarray, np.ndarray]:
        mean = _array("Gaussian.mean", mean, 2)
        cov = _array("Gaussian.cov", cov, 3)
        if cov.shape != (mean.shape[0], mean.shape[1], mean.shape[1]):
            raise InputError(f"Gaussian.cov must have shape {(mean.shape[0], mean.shape[1], mean.shape[1])} "
                             f"to match mean {mean.shape}, got {cov.shape}")
        _require_finite("Gaussian.mean", mean)
        _require_finite("Gaussian.cov", cov)
        return mean, cov

    @classmethod
    def trusted(cls, mean, cov) -> "Gaussian":
        """A Gaussian whose covariances the caller's algebra keeps symmetric and positive semi-definite: shapes and
        finiteness are checked, the (costlier) eigenvalue test is not."""
        mean, cov = cls._checked(mean, cov)
        return _validated(cls, mean=mean, cov=cov)

    @classmethod
    def kernel_output(cls, mean: np.ndarray, cov: np.ndarray) -> "Gaussian":
        """A Gaussian from a compiled filter step that has itself done every check :meth:`trusted` does: ``mean``
        and ``cov`` are float64 arrays it allocated (``np.empty``) with the shapes of the checked Gaussian it started
        from, and it has checked every number it wrote finite (declining otherwise, so that its
        caller takes the NumPy path, whose :meth:`trusted` names the problem).  Nothing is checked here: a one-track
        step spends most of :meth:`trusted`'s time (about a third of a step) re-reading what the loop just wrote.
        Filter code only; anything else builds a Gaussian with the constructor or :meth:`trusted`."""
        out = object.__new__(cls)
        fields = out.__dict__  # what _validated does, without its loop: this runs twice a one-track step
        fields["mean"] = mean
        fields["cov"] = cov
        return out

    @property
    def batch(self) -> int:
        return self.mean.shape[0]

    @property
    def dim(self) -> int:
        return self.mean.shape[1]

    def take(self, index) -> "Gaussian":
        """The sub-batch ``index`` (an int keeps a batch axis of one)."""
        index = np.atleast_1d(index) if np.isscalar(index) else index
        return Gaussian.trusted(self.mean[index], self.cov[index])

    @classmethod
    def broadcast(cls, mean, cov, batch: int) -> "Gaussian":
        """One belief ``mean (n,)``, ``cov (n, n)`` repeated over a batch of ``batch`` (``>= 1``, within half the
        machine's memory)."""
        mean = _as_array("Gaussian.broadcast: mean", mean)
        cov = _as_array("Gaussian.broadcast: cov", cov)
        batch = check_size("Gaussian.broadcast: batch", batch, 8.0 * (mean.size + cov.size))
        return cls(np.broadcast_to(mean, (batch, *mean.shape)).copy(),
                   np.broadcast_to(cov, (batch, *cov.shape)).copy())


#: Particle sets up to this size get their moments from BLAS products in :meth:`Particles.to_gaussian`.
BLAS_MOMENT_PARTICLES = 4096


@dataclass(frozen=True)
class Particles:
    """A batch of weighted particle sets.

    Shapes
    ------
    particles : (B, N, n)
    log_weights : (B, N), normalised so that ``logsumexp(log_weights, axis=1) == 0``
    """

    particles: np.ndarray
    log_weights: np.ndarray

    #: The batch-first fields: how a tracker takes and joins batch items (:func:`workbench.specs.take_batch`).
    batch_fields = ("particles", "log_weights")

    def __post_init__(self) -> None:
        x, lw = self._checked(self.particles, self.log_weights)
        _require_finite("Particles.particles", x)
        if lw.size:
            from scipy.special import logsumexp

            with np.errstate(invalid="ignore"):
                total = logsumexp(lw, axis=1)
            bad = ~(np.abs(total) <= WEIGHT_TOL) | np.isnan(lw).any(axis=1)
            if np.any(bad):
                item = int(np.argmax(bad))
                raise InputError(f"Particles.log_weights of item {item} are not normalised (logsumexp = "
                                 f"{total[item]:.3g}; expected 0) or hold NaN")
        object.__setattr__(self, "particles", x)
        object.__setattr__(self, "log_weights", lw)

    @staticmethod
    def _checked(particles, log_weights) -> tuple[np.ndarray, np.ndarray]:
        x = _array("Particles.particles", particles, 3)
        lw = _array("Particles.log_weights", log_weights, 2)
        if lw.shape != x.shape[:2]:
            raise InputError(f"Particles.log_weights must have shape {x.shape[:2]}, got {lw.shape}")
        if x.shape[1] < 1:
            raise InputError("Particles needs at least one particle per item, got N = 0")
        return x, lw

    @classmethod
    def trusted(cls, particles, log_weights) -> "Particles":
        """Particles from filter code that keeps them finite and normalised: shapes (and N >= 1) are checked, the
        per-particle scans are not."""
        x, lw = cls._checked(particles, log_weights)
        return _validated(cls, particles=x, log_weights=lw)

    @property
    def weights(self) -> np.ndarray:
        return np.exp(self.log_weights)

    def to_gaussian(self) -> Gaussian:
        """Weighted mean and covariance of each particle set.

        Up to :data:`BLAS_MOMENT_PARTICLES` particles per set: two matrix products.  Beyond that, one
        weighted dot product over the particles per component (pair), for any memory layout: measured
        4x faster at N = 10^5 than the products with their ``(B, N, n)`` temporaries.
        """
        w = self.weights
        x = self.particles
        B, N, n = x.shape
        if N <= BLAS_MOMENT_PARTICLES:
            mean = np.matmul(w[:, None, :], x)[:, 0, :]  # sum_i w_i x_i
            d = x - mean[:, None, :]
            cov = np.matmul(np.swapaxes(d * w[..., None], 1, 2), d)  # sum_i w_i d_i d_i^T (one BLAS call)
            return Gaussian.trusted(mean, 0.5 * (cov + np.swapaxes(cov, 1, 2)))
        mean = np.empty((B, n))
        for j in range(n):
            mean[:, j] = np.einsum("bn,bn->b", w, x[..., j])  # sum_i w_i x_ij
        d = [x[..., j] - mean[:, j, None] for j in range(n)]
        cov = np.empty((B, n, n))
        for i in range(n):
            wd = w * d[i]
            for j in range(i, n):
                cov[:, i, j] = cov[:, j, i] = np.einsum("bn,bn->b", wd, d[j])  # sum_k w_k d_ki d_kj
        return Gaussian.trusted(mean, cov)


def _scan_cov(cls_name: str, cov, z: np.ndarray, valid: np.ndarray):
    """Per-detection covariances ``(..., M, m, m)``: symmetric, finite and PSD on the valid rows."""
    if cov is None:
        return None
    m = z.shape[-1]
    cov = _as_array(f"{cls_name}.cov", cov)
    if cov.shape != z.shape + (m,):
        raise InputError(f"{cls_name}.cov must have shape {z.shape + (m,)}, got {cov.shape}")
    rows = cov[valid]
    if not np.all(np.isfinite(rows)):
        raise InputError(f"{cls_name}.cov holds NaN or inf for a valid detection")
    if rows.size:
        if not np.allclose(rows, np.swapaxes(rows, -1, -2), rtol=1e-9, atol=1e-12):
            raise InputError(f"{cls_name}.cov must be symmetric for every valid detection")
        scale = np.maximum(np.abs(rows).max(axis=(-2, -1)), 1e-300)
        if np.any(np.linalg.eigvalsh(rows).min(axis=-1) < -1e-9 * scale):
            raise InputError(f"{cls_name}.cov must be positive semi-definite for every valid detection")
    eye = np.broadcast_to(np.eye(m), cov.shape)
    return np.where(valid[..., None, None], cov, eye)


def _scan_fields(cls_name: str, z, valid, extra: dict, lead: int):
    z = _array(f"{cls_name}.z", z, lead + 2)
    valid = _array(f"{cls_name}.valid", valid, lead + 1, dtype=bool)
    if valid.shape != z.shape[:-1]:
        raise InputError(f"{cls_name}.valid must have shape {z.shape[:-1]} to match z {z.shape}, got {valid.shape}")
    # (B, T, M)-sized boolean temporaries only: a full-size scan series is not copied to be checked
    bad = valid & ~np.all(np.isfinite(z), axis=-1)
    if bad.any():
        raise InputError(f"{cls_name}.z holds NaN or inf in a valid measurement at index "
                         f"{tuple(int(i) for i in np.argwhere(bad)[0])}; mark padding rows invalid instead")
    dirty = ~valid & np.any(z != 0.0, axis=-1)  # padding rows not yet zeroed (NaN counts as not zero)
    out = {"z": np.where(valid[..., None], z, 0.0) if dirty.any() else z, "valid": valid}
    for key, value in extra.items():
        if value is None:
            out[key] = None
            continue
        dtype = int if key == "origin" else float
        arr = _as_array(f"{cls_name}.{key}", value, dtype)
        if arr.shape != valid.shape:
            raise InputError(f"{cls_name}.{key} must have shape {valid.shape}, got {arr.shape}")
        out[key] = arr
    return out


def _validated(cls, **values):
    """An instance of the frozen dataclass ``cls`` from values already validated by an instance of the same
    kind (a slice of a checked :class:`Scans`, a checked :class:`Scan` without its labels): no second check."""
    out = object.__new__(cls)
    for key, value in values.items():
        object.__setattr__(out, key, value)
    return out


def _replaced(obj, **changes):
    """``obj`` (a frozen dataclass) with some fields changed, without re-running its ``__init__`` and checks: the
    new values are already valid (a sub-batch of checked arrays, a model bound to a step's time)."""
    return _validated(type(obj), **{**vars(obj), **changes})


@dataclass(frozen=True)
class Scan:
    """The detections of one scan for a batch, padded to a common count ``M``.

    ``origin`` says which truth object produced each detection (``CLUTTER`` = -1 for clutter). It is
    for metrics only: :meth:`for_filter` strips it before a filter sees the scan.

    Shapes
    ------
    z : (B, M, m); invalid (padding) rows are zeroed
    valid : (B, M) bool
    snr, doppler : (B, M) or None (SNR in dB, Doppler as the sensor defines it)
    origin : (B, M) int or None
    cov : (B, M, m, m) or None, each detection's own measurement covariance (used in place of the model's
        ``R`` by filters with the ``detection_covariance`` capability)
    clutter_density : (B, M) or None, the density of clutter at each detection per unit measurement volume
        (used by filters with the ``clutter_density`` capability)
    """

    z: np.ndarray
    valid: np.ndarray
    snr: np.ndarray | None = None
    doppler: np.ndarray | None = None
    origin: np.ndarray | None = None
    time: float = 0.0
    cov: np.ndarray | None = None
    clutter_density: np.ndarray | None = None

    def __post_init__(self) -> None:
        fields_ = _scan_fields("Scan", self.z, self.valid,
                               {"snr": self.snr, "doppler": self.doppler, "origin": self.origin,
                                "clutter_density": self.clutter_density}, 1)
        for key, value in fields_.items():
            object.__setattr__(self, key, value)
        object.__setattr__(self, "cov", _scan_cov("Scan", self.cov, self.z, self.valid))
        object.__setattr__(self, "time", real_scalar("Scan.time", self.time))
        if not np.isfinite(self.time):
            raise InputError(f"Scan.time must be finite, got {self.time}")

    @property
    def batch(self) -> int:
        return self.z.shape[0]

    @property
    def counts(self) -> np.ndarray:
        """Number of valid detections per batch item, ``(B,)``."""
        return self.valid.sum(axis=1)

    def for_filter(self) -> "Scan":
        """The same scan without the origin labels."""
        return _validated(Scan, z=self.z, valid=self.valid, snr=self.snr, doppler=self.doppler, origin=None,
                          time=self.time, cov=self.cov, clutter_density=self.clutter_density)

    @classmethod
    def empty(cls, batch: int, dim: int, time: float = 0.0) -> "Scan":
        """A scan with no detections for ``batch`` items of measurement dimension ``dim``."""
        batch = check_size("Scan.empty: batch", batch, 1.0)
        dim = check_size("Scan.empty: dim", dim, 1.0)
        return cls(np.zeros((batch, 0, dim)), np.zeros((batch, 0), dtype=bool), time=time)

    @classmethod
    def single(cls, z, present=None, time: float = 0.0, cov=None, clutter_density=None) -> "Scan":
        """One measurement per batch item, ``z (B, m)``; ``present (B,)`` marks missed detections; ``cov
        (B, m, m)`` and ``clutter_density (B,)`` as :class:`Scan` declares them.  A 1-D ``z`` is refused (it could
        be ``B`` scalar measurements or one item's vector): write ``z[:, None]`` or ``z[None, :]``."""
        z = _as_array("Scan.single: z", z)
        if z.ndim != 2:
            raise InputError(f"Scan.single: z must have shape (B, m), one measurement of m components per batch "
                             f"item; got shape {z.shape}"
                             + ("; write z[:, None] for B scalar measurements or z[None, :] for one item's "
                                "measurement" if z.ndim == 1 else ""))
        present = (np.ones(z.shape[0], dtype=bool) if present is None
                   else _as_array("Scan.single: present", present, bool))
        if present.shape != z.shape[:1]:
            raise InputError(f"Scan.single: present must have shape {z.shape[:1]} to match z {z.shape}, got "
                             f"{present.shape}")
        if cov is not None:
            cov = _as_array("Scan.single: cov", cov)
            if cov.shape != (z.shape[0], z.shape[1], z.shape[1]):
                raise InputError(f"Scan.single: cov must have shape {(z.shape[0], z.shape[1], z.shape[1])}, got "
                                 f"{cov.shape}")
        if clutter_density is not None:
            clutter_density = _as_array("Scan.single: clutter_density", clutter_density)
            if clutter_density.shape != z.shape[:1]:
                raise InputError(f"Scan.single: clutter_density must have shape {z.shape[:1]}, got "
                                 f"{clutter_density.shape}")
        return cls(z[:, None, :], present[:, None], time=time, cov=None if cov is None else cov[:, None],
                   clutter_density=None if clutter_density is None else clutter_density[:, None])


@dataclass(frozen=True)
class Scans:
    """A scenario's scans for a batch: the time axis ``T`` after the batch axis.

    Shapes
    ------
    z : (B, T, M, m)
    valid : (B, T, M)
    snr, doppler, origin, clutter_density : (B, T, M) or None
    cov : (B, T, M, m, m) or None
    times : (T,), finite and strictly increasing
    """

    z: np.ndarray
    valid: np.ndarray
    times: np.ndarray
    snr: np.ndarray | None = None
    doppler: np.ndarray | None = None
    origin: np.ndarray | None = None
    cov: np.ndarray | None = None
    clutter_density: np.ndarray | None = None

    def __post_init__(self) -> None:
        fields_ = _scan_fields("Scans", self.z, self.valid,
                               {"snr": self.snr, "doppler": self.doppler, "origin": self.origin,
                                "clutter_density": self.clutter_density}, 2)
        for key, value in fields_.items():
            object.__setattr__(self, key, value)
        object.__setattr__(self, "cov", _scan_cov("Scans", self.cov, self.z, self.valid))
        times = _array("Scans.times", self.times, 1)
        if times.shape[0] != self.z.shape[1]:
            raise InputError(f"Scans.times must have length {self.z.shape[1]}, got {times.shape[0]}")
        _require_finite("Scans.times", times)
        if times.size > 1 and np.any(np.diff(times) <= 0):
            k = int(np.argmax(np.diff(times) <= 0))
            raise InputError(f"Scans.times must be strictly increasing; scan {k + 1} at {times[k + 1]} s does not "
                             f"follow scan {k} at {times[k]} s")
        object.__setattr__(self, "times", times)

    @property
    def batch(self) -> int:
        return self.z.shape[0]

    @property
    def steps(self) -> int:
        return self.z.shape[1]

    def scan(self, k: int) -> Scan:
        """Scan ``k`` as a :class:`Scan`."""
        pick = lambda a: None if a is None else a[:, k]  # noqa: E731
        return _validated(Scan, z=self.z[:, k], valid=self.valid[:, k], snr=pick(self.snr),
                          doppler=pick(self.doppler), origin=pick(self.origin), time=float(self.times[k]),
                          cov=pick(self.cov), clutter_density=pick(self.clutter_density))

    def head(self, steps: int) -> "Scans":
        """The first ``steps`` scans."""
        pick = lambda a: None if a is None else a[:, :steps]  # noqa: E731
        return _validated(Scans, z=self.z[:, :steps], valid=self.valid[:, :steps], times=self.times[:steps],
                          snr=pick(self.snr), doppler=pick(self.doppler), origin=pick(self.origin),
                          cov=pick(self.cov), clutter_density=pick(self.clutter_density))

    def take(self, index) -> "Scans":
        """The sub-batch ``index`` of runs (an int keeps a batch axis of one)."""
        index = np.atleast_1d(index) if np.isscalar(index) else index
        pick = lambda a: None if a is None else a[index]  # noqa: E731
        return _validated(Scans, z=self.z[index], valid=self.valid[index], times=self.times, snr=pick(self.snr),
                          doppler=pick(self.doppler), origin=pick(self.origin), cov=pick(self.cov),
                          clutter_density=pick(self.clutter_density))

    @property
    def intervals(self) -> np.ndarray:
        """The time step before each scan, ``(T,)`` (the first is the second's, or 0 for a single scan)."""
        dt = np.diff(self.times)
        return np.concatenate([dt[:1] if dt.size else np.zeros(1), dt])

    def with_valid(self, valid) -> "Scans":
        """The same detections with a narrower mask (what a clutter remover returns)."""
        valid = _as_array("the clutter remover's mask", valid, bool)
        if valid.shape != self.valid.shape:
            raise InputError(f"a clutter remover must return a mask of shape {self.valid.shape}, got {valid.shape}")
        return replace(self, valid=valid & self.valid)

    def merge(self, other: "Scans") -> "Scans":
        """Concatenate the detections of two scan series along the detection axis ``M``."""
        return Scans.merge_all([self, other])

    @staticmethod
    def merge_all(parts: list) -> "Scans":
        """Concatenate the detections of every scan series in ``parts`` along ``M``, emptying the list.

        Each field's inputs are released as soon as its output is built, so where the list holds the only
        references (``Scans.merge_all([sensor.simulate(...), clutter.generate(...)])``) a merge of full-size series
        holds the inputs plus one output field, not the inputs plus every output.  A field missing from some parts
        is filled (``snr``, ``doppler``, ``clutter_density``: NaN; ``origin``: ``CLUTTER``); per-detection ``cov``
        must be given by all parts or none.
        """
        if not parts:
            raise InputError("cannot merge an empty list of scan series")
        first = other = parts[0]
        for other in parts[1:]:
            if other.z.shape[:2] != first.z.shape[:2] or other.z.shape[3] != first.z.shape[3]:
                raise InputError(f"cannot merge scans of shapes {first.z.shape} and {other.z.shape}")
            if not np.allclose(first.times, other.times, rtol=1e-12, atol=1e-9):
                raise InputError("cannot merge scan series with different time stamps")
        if len({p.cov is None for p in parts}) > 1:
            raise InputError("cannot merge a scan series that carries per-detection covariances (cov) with one "
                             "that does not; give both, or neither")
        names = ("z", "valid", "snr", "doppler", "origin", "cov", "clutter_density")
        fields = {name: [getattr(p, name) for p in parts] for name in names}
        shapes = [p.valid.shape for p in parts]
        times = first.times
        del first, other
        parts.clear()  # from here on only ``fields`` holds the inputs
        fills = {"snr": np.nan, "doppler": np.nan, "origin": CLUTTER, "clutter_density": np.nan}
        out = {}
        for name in names:
            arrays = fields.pop(name)
            if all(a is None for a in arrays):
                out[name] = None
                continue
            if name in fills:
                arrays = [np.full(shape, fills[name]) if a is None else a for a, shape in zip(arrays, shapes)]
            out[name] = np.concatenate(arrays, axis=2)
            del arrays
        return Scans(out.pop("z"), out.pop("valid"), times, **out)


@dataclass(frozen=True)
class Truth:
    """True object states over time.

    Shapes
    ------
    states : (B, T, n)
    times : (T,)
    """

    states: np.ndarray
    times: np.ndarray
    labels: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        states = _array("Truth.states", self.states, 3)
        times = _array("Truth.times", self.times, 1)
        if times.shape[0] != states.shape[1]:
            raise InputError(f"Truth.times must have length {states.shape[1]}, got {times.shape[0]}")
        _require_finite("Truth.states", states)
        object.__setattr__(self, "states", states)
        object.__setattr__(self, "times", times)

    @property
    def batch(self) -> int:
        return self.states.shape[0]

    @property
    def steps(self) -> int:
        return self.states.shape[1]
