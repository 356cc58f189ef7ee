"""The one kernel-backend policy: which implementation of a compiled kernel runs, and on which arch.

Every kernel of :mod:`workbench.kernels` has a NumPy twin (the reference its tests hold every backend to) and a
Numba version for the CPU; the particle-filter weight kernels also have a Taichi version for any arch (a kernel
without one runs its NumPy twin off the CPU).  A kernel asks :func:`resolve` which to run:

- ``backend="auto"`` on ``arch="cpu"``: Numba where it is installed (its CPU code vectorises with AVX/FMA), else
  Taichi;
- ``backend="auto"`` on ``"cuda"``, ``"vulkan"`` or ``"metal"``: Taichi on that arch;
- ``"numba"``, ``"taichi"`` or ``"numpy"``: that one (``"numpy"``: the reference twin, for tests and ablations).

The arch is process-wide, as the Taichi runtime is: the report engine and the command line set it for the
duration of a run with :func:`using` (``workbench report --arch cuda``), and filters never carry it.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import threading
from collections import Counter
from typing import Iterator

__all__ = ["BACKENDS", "ARCHES", "numba_available", "current_arch", "using", "set_arch", "resolve", "BackendRecord"]

#: Backend names a kernel call or a filter parameter may give.
BACKENDS = ("auto", "numba", "taichi", "numpy")
#: Arch names of the policy (``"auto"``: the first GPU Taichi finds, else the CPU).
ARCHES = ("cpu", "cuda", "vulkan", "metal", "auto")

_state = {"arch": "cpu"}


@functools.lru_cache(maxsize=None)
def numba_available() -> bool:
    """Whether Numba is installed (a dependency; an install without it falls back to Taichi on the CPU)."""
    return importlib.util.find_spec("numba") is not None


def current_arch() -> str:
    """The arch kernels run on now (``"cpu"`` unless :func:`using` or :func:`set_arch` chose another)."""
    return _state["arch"]


def set_arch(arch: str) -> str:
    """Make ``arch`` the process's kernel arch; returns the previous one."""
    if arch not in ARCHES:
        raise ValueError(f"unknown kernel arch {arch!r}; expected one of {', '.join(ARCHES)}")
    previous, _state["arch"] = _state["arch"], arch
    return previous


@contextlib.contextmanager
def using(arch: str | None) -> Iterator[str]:
    """Run the body with kernels on ``arch`` (``None``: leave it as it is)."""
    if arch is None:
        yield current_arch()
        return
    previous = set_arch(arch)
    try:
        yield arch
    finally:
        set_arch(previous)


def resolve(backend: str = "auto", arch: str | None = None) -> str:
    """The implementation to run: ``"numba"``, ``"taichi"`` or ``"numpy"`` (see the module docstring).

    ``arch`` defaults to :func:`current_arch`.  Asking for Numba off the CPU, or without Numba installed, is an
    error rather than a silent substitute.
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown kernel backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    arch = current_arch() if arch is None else arch
    if backend == "numba":
        if not numba_available():
            raise ValueError("backend 'numba' needs numba, a dependency of the workbench that this install lacks "
                             "(pip install numba)")
        if arch not in ("cpu",):
            raise ValueError(f"backend 'numba' runs on the CPU only, not on arch {arch!r}")
        return "numba"
    if backend != "auto":
        return backend
    return "numba" if arch == "cpu" and numba_available() else "taichi"


class _PerThread(threading.local):
    def __init__(self) -> None:
        self.last: str | None = None
        self.counts: Counter = Counter()


class BackendRecord:
    """Which code a function with a silent fallback actually ran, per thread: the last call's backend and a tally
    of calls per backend (``"numba"``, ``"numpy"``, ...).  A module that may fall back from its compiled loops to
    its NumPy code notes each call here, so that tests can assert which path ran rather than trust it."""

    def __init__(self) -> None:
        self._local = _PerThread()

    def note(self, backend: str) -> None:
        """Record that one call ran ``backend``."""
        local = self._local
        local.last = backend
        local.counts[backend] += 1

    def last(self) -> str | None:
        """The backend of this thread's last call (``None`` before the first)."""
        return self._local.last

    def counts(self) -> dict:
        """Calls per backend in this thread so far (a copy)."""
        return dict(self._local.counts)
