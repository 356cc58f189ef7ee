"""The one kernel-backend policy: which implementation of a compiled kernel runs, and on which arch.

Every kernel of :mod:`workbench.kernels` has a NumPy twin (the reference its tests hold every backend to) and a
Numba version for the CPU; the particle-filter weight kernels also have a Taichi version for any arch (a kernel
without one runs its NumPy twin off the CPU).  A kernel asks :func:`resolve` which to run:

- ``backend="auto"`` on ``arch="cpu"``: Numba where it is installed (its CPU code vectorises with AVX/FMA), else
  Taichi;
- ``backend="auto"`` on ``"cuda"``, ``"vulkan"`` or ``"metal"``: Taichi on that arch;
- ``"numba"``, ``"taichi"`` or ``"numpy"``: that one (``"numpy"``: the reference twin, for tests and ablations).

``"auto"`` is the policy's choice, and the environment variable ``WORKBENCH_BACKEND`` (:data:`ENV`, read once, at
the process's first kernel choice; a report's worker processes inherit it) may make that choice for the process:
``WORKBENCH_BACKEND=numpy`` runs every kernel's NumPy twin wherever a caller left the backend to the policy (a
backend a caller names explicitly, a filter's ``backend="numba"``, is honoured as given); :func:`preferring` does
the same for the duration of a block.  A module with only a Numba and a NumPy version asks :func:`runs_numba`.

This module is the only place that names arches (:data:`ARCHES`: the command line's ``--arch`` choices and
:func:`workbench.kernels.runtime.ensure_taichi` read it) and the only place that decides between compiled and
NumPy code: nothing else calls :func:`numba_available` to pick a path (``tests/test_backend_policy.py`` greps the
source tree for that, for ``import numba`` / ``import taichi`` outside the compiled twins, and for arch lists).
A module whose choice may fall back notes each call's backend in a :class:`BackendRecord`.

The arch is process-wide, as the Taichi runtime is: the report engine and the command line set it for the
duration of a run with :func:`using` (``workbench report --arch cuda``), and filters never carry it.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import os
import threading
from collections import Counter
from typing import Iterator

__all__ = ["BACKENDS", "ARCHES", "GPU_ARCHES", "RUN_ARCHES", "ENV", "numba_available", "current_arch", "using",
           "set_arch", "default_backend", "preferring", "resolve", "runs_numba", "threaded", "BackendRecord"]

#: Backend names a kernel call or a filter parameter may give.
BACKENDS = ("auto", "numba", "taichi", "numpy")
#: The GPU arches (Taichi's names; :mod:`.runtime` starts Taichi on them).
GPU_ARCHES = ("cuda", "vulkan", "metal")
#: The arches kernels can run on (what ``workbench bench --arch`` takes).
RUN_ARCHES = ("cpu",) + GPU_ARCHES
#: Arch names of the policy (``"auto"``: the first GPU Taichi finds, else the CPU): the one list of them.
ARCHES = RUN_ARCHES + ("auto",)
#: The environment variable that makes the policy's ``"auto"`` choice for the process (one of :data:`BACKENDS`).
ENV = "WORKBENCH_BACKEND"

_state = {"arch": "cpu", "default": None}  # "default": what "auto" stands for (None: read ENV on first use)


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


def _from_environment() -> str:
    value = os.environ.get(ENV)
    if not value:
        return "auto"
    if value not in BACKENDS:
        from ..types import InputError

        raise InputError(f"environment variable {ENV}={value!r} is not a kernel backend; expected one of "
                         f"{', '.join(BACKENDS)}")
    return value


def default_backend() -> str:
    """What ``"auto"`` stands for in this process: the backend of an enclosing :func:`preferring` block, else the
    value of ``WORKBENCH_BACKEND`` (:data:`ENV`, read once, when first needed) where it is set and not empty, else
    ``"auto"`` (the policy's own choice by arch).  A value of the variable that is not one of :data:`BACKENDS` is
    refused naming the variable."""
    value = _state["default"]
    if value is None:
        value = _state["default"] = _from_environment()
    return value


@contextlib.contextmanager
def preferring(backend: str) -> Iterator[str]:
    """Run the body with ``backend`` standing for ``"auto"`` (``"numpy"``: every NumPy twin; ``"auto"``: the policy's
    own choice, whatever ``WORKBENCH_BACKEND`` says), as ``WORKBENCH_BACKEND`` does for a whole process."""
    if backend not in BACKENDS:
        raise ValueError(f"unknown kernel backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    previous, _state["default"] = _state["default"], backend
    try:
        yield backend
    finally:
        _state["default"] = previous


def resolve(backend: str = "auto", arch: str | None = None) -> str:
    """The implementation to run: ``"numba"``, ``"taichi"`` or ``"numpy"`` (see the module docstring).

    ``arch`` defaults to :func:`current_arch`; ``"auto"`` is :func:`default_backend` (``WORKBENCH_BACKEND``) where
    that is set.  Asking for Numba off the CPU, or without Numba installed, is an error rather than a silent
    substitute.
    """
    arch = _state["arch"] if arch is None else arch
    source = "backend 'numba'"
    if backend == "auto":
        backend = _state["default"] or default_backend()
        if backend == "auto" and arch == "cpu":  # the common case first: it runs on every filter step
            return "numba" if numba_available() else "taichi"
        source = f"the preferred backend 'numba' ({ENV} or preferring)"
    elif backend not in BACKENDS:
        raise ValueError(f"unknown kernel backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    if arch not in ARCHES:
        raise ValueError(f"unknown kernel arch {arch!r}; expected one of {', '.join(ARCHES)}")
    if backend == "numba":
        if not numba_available():
            raise ValueError(f"{source} needs numba, a dependency of the workbench that this install lacks "
                             "(pip install numba)")
        if arch != "cpu":
            raise ValueError(f"{source} runs on the CPU only, not on arch {arch!r}")
        return "numba"
    if backend != "auto":
        return backend
    return "taichi"  # "auto" off the CPU (a GPU arch, or "auto": Taichi picks)


def runs_numba(backend: str = "auto", arch: str | None = None) -> bool:
    """Whether a module that has only a Numba version and its NumPy twin runs the Numba one: :func:`resolve`
    gives ``"numba"`` (``"taichi"``, off the CPU or without Numba, means the NumPy twin there)."""
    return resolve(backend, arch) == "numba"


def threaded(items: int, threshold: int) -> bool:
    """Whether a compiled kernel with a threaded and a serial compilation of the same loops (the same numbers
    either way: one item per parallel iteration, no reduction across items) should run the threaded one: at least
    ``threshold`` items (below that, waking the thread pool costs more than the work) and more than one Numba
    thread in this process.  A report's worker processes run one thread each (:data:`workbench.report.engine.
    ONE_THREAD_ENV`): there the threaded compilation would only cost its compile time (a parallel region is
    compiled, cached and loaded apart from the serial one) and never run anything in parallel."""
    if items < threshold:
        return False
    import numba

    return numba.get_num_threads() > 1


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
