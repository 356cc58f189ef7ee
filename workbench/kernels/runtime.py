"""Lazy start-up of the Taichi runtime, shared by every Taichi kernel module of the workbench.

Importing the workbench never imports or initialises Taichi.  A kernel wrapper calls
:func:`ensure_taichi` right before its first launch; the runtime then stays up for the process.
A runtime that someone else already started on the same arch is reused as it is (``ti.init`` would
reset it and invalidate that code's fields and ndarrays).

Arch names are the backend policy's (:data:`workbench.kernels.backend.ARCHES`: the CPU, a GPU arch of
:data:`~workbench.kernels.backend.GPU_ARCHES`, or ``"auto"``: the first GPU Taichi finds, else the CPU with a
one-line notice on stderr).  An explicitly named GPU arch that is not available raises :class:`TaichiUnavailable`
instead of quietly running somewhere else.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys

from .backend import ARCHES, GPU_ARCHES

__all__ = ["ARCHES", "TaichiUnavailable", "ensure_taichi", "current_arch", "taichi_available_arches"]

#: Taichi's names of its CPU arches (every other arch is named as the policy names it).
_CPU_NAMES = {"x64": "cpu", "arm64": "cpu"}


class TaichiUnavailable(RuntimeError):
    """The requested Taichi arch cannot be started on this machine."""


def _floating_point_environment():
    """Save and restore the process's floating-point environment (rounding, exception masks and, on x86-64,
    MXCSR's flush-to-zero and denormals-are-zero bits) with C's ``fegetenv``/``fesetenv``; ``None`` where the C
    library does not offer them."""
    try:
        import ctypes
        import ctypes.util

        libm = ctypes.CDLL(ctypes.util.find_library("m") or None)
        env = ctypes.create_string_buffer(512)  # larger than any fenv_t
        if libm.fegetenv(env) != 0:
            return None
        return lambda: libm.fesetenv(env)
    except (OSError, AttributeError):  # pragma: no cover - no C maths library to ask
        return None


def _import_taichi():
    # Quiet the import banner and the version-check thread unless the user asked for them.
    os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")
    os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")
    import taichi as ti

    return ti


def current_arch() -> str | None:
    """The arch of the running Taichi runtime (``"cpu"`` or a name of :data:`GPU_ARCHES`), or ``None``."""
    if "taichi" not in sys.modules:
        return None
    from taichi.lang import impl

    if impl.get_runtime().prog is None:
        return None
    from taichi._lib import core as _ti_core

    name = _ti_core.arch_name(impl.current_cfg().arch)
    return _CPU_NAMES.get(name, name)


def taichi_available_arches() -> tuple[str, ...]:
    """The arches Taichi can use here, CPU first (tests run kernels on each)."""
    ti = _import_taichi()
    found = ["cpu"]
    for name in GPU_ARCHES:
        with contextlib.suppress(Exception):
            if ti.lang.misc.is_arch_supported(getattr(ti, name)):
                found.append(name)
    return tuple(found)


def ensure_taichi(arch: str = "cpu") -> str:
    """Start Taichi on ``arch`` unless it already runs there; return the arch in use.

    ``"auto"`` keeps whatever runtime is already up, else tries the GPUs and falls back to the CPU
    with a one-line notice.  Asking for a different arch than the running one restarts Taichi
    (``ti.init`` resets the runtime; kernels recompile on their next launch).

    Parameters
    ----------
    arch : str
        A name of :data:`ARCHES` (the backend policy's list).
    """
    if arch not in ARCHES:
        raise ValueError(f"unknown Taichi arch {arch!r}; expected one of {', '.join(ARCHES)}")
    running = current_arch()
    if running is not None and (arch == "auto" or arch == running):
        return running
    ti = _import_taichi()
    if arch in GPU_ARCHES and arch not in taichi_available_arches():
        # Checked before ti.init, which would first reset a runtime that is already running.
        raise TaichiUnavailable(f"Taichi cannot start on arch {arch!r} here (not available); use 'cpu' or 'auto'")
    # "auto": the GPU arches in the policy's order (ti.init takes the first it can start)
    wanted = ti.cpu if arch == "cpu" else [getattr(ti, a) for a in GPU_ARCHES] if arch == "auto" else getattr(ti, arch)
    # ti.init turns on flush-to-zero and denormals-are-zero for the whole process (Python and NumPy arithmetic
    # included: 5e-324 * 1.0 becomes 0.0), so results computed after a Taichi kernel would differ from those
    # computed before it.  The calling thread's floating-point environment is restored after it.
    restore = _floating_point_environment()
    with contextlib.redirect_stdout(io.StringIO()):  # ti.init prints "[Taichi] Starting on arch=..."
        ti.init(arch=wanted, enable_fallback=(arch == "auto"), offline_cache=True, log_level="warn")
    if restore is not None:
        restore()
    running = current_arch()
    if arch == "auto" and running == "cpu":
        print("workbench: no GPU available to Taichi; kernels run on the CPU", file=sys.stderr)
    return running
