"""Freed memory kept for reuse: glibc malloc's thresholds for the workbench's own processes.

A particle filter allocates arrays of megabytes every step (the states, weights and parents of ``B x N``
particles).  glibc's malloc serves a block above its *mmap threshold* (128 KiB at start, raised dynamically up to
32 MiB) with fresh pages from the kernel and hands them back when the block is freed; below it, a freed block stays
in the heap, but the heap's top is handed back once more than the *trim threshold* (twice the mmap threshold) is
free.  Which happens depends on what else the process holds: the bootstrap filter at N = 10^5 ran 17-20 ns per
particle-step, and 31-37 ns once two 3.2 MB arrays were alive beside it, because each step then faulted about 550
new pages in (a page fault with its zeroing costs microseconds on a VM).  The full report took 3.4 million page
faults.

:func:`keep_freed_memory` fixes both thresholds high (:data:`MMAP_THRESHOLD`, :data:`TRIM_THRESHOLD`), so a freed
block is reused by the next step instead of being returned and faulted in again; :data:`MALLOC_ENV` is the same
setting for a process about to start (glibc reads it at start-up).  The numbers computed do not change (only where
memory comes from).  The price: up to :data:`TRIM_THRESHOLD` of freed memory stays with the process until it ends
or frees more.  The command line's commands apply it to their own process and the report's worker processes; a
program that imports the workbench keeps its C library's defaults unless it calls :func:`keep_freed_memory`.
Elsewhere than glibc (musl, macOS, Windows) nothing is changed.
"""

from __future__ import annotations

import os

__all__ = ["MMAP_THRESHOLD", "TRIM_THRESHOLD", "MALLOC_ENV", "keep_freed_memory", "malloc_env"]

#: Blocks below this size come from the heap and are reused once freed (bytes; 256 MiB).
MMAP_THRESHOLD = 256 * 1024 * 1024
#: Free memory at the heap's top beyond this is handed back to the system (bytes; 512 MiB).
TRIM_THRESHOLD = 512 * 1024 * 1024
#: glibc's names for the same two settings in a new process's environment (read once, at its start).
MALLOC_ENV = {"MALLOC_MMAP_THRESHOLD_": str(MMAP_THRESHOLD), "MALLOC_TRIM_THRESHOLD_": str(TRIM_THRESHOLD)}

# mallopt's parameter numbers (malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: glibc releases before 2.35 refuse an mmap threshold above half their heap size (32 MiB on 64-bit systems).
_OLD_GLIBC_LIMIT = 32 * 1024 * 1024


def _glibc_version() -> tuple[int, ...] | None:
    """This process's glibc release, e.g. ``(2, 36)``, from the C library's own answer (``confstr``, not a scan of
    the executable: ``platform.libc_ver`` reads the interpreter's file, megabytes for a static build, at every
    call); ``None`` off glibc."""
    try:
        text = os.confstr("CS_GNU_LIBC_VERSION") or ""
    except (AttributeError, ValueError, OSError):  # no confstr, or no such name (not glibc)
        return None
    name, _, release = text.partition(" ")
    if name != "glibc":
        return None
    parts = []
    for part in release.split("."):
        if not part.isdigit():
            break
        parts.append(int(part))
    return tuple(parts)


def _glibc() -> bool:
    """Whether this process runs on glibc."""
    return _glibc_version() is not None


def _mmap_threshold() -> int:
    """The mmap threshold this glibc accepts: :data:`MMAP_THRESHOLD`, or 32 MiB before 2.35, which ignores a larger
    value (and a new process's ``MALLOC_TRIM_THRESHOLD_`` would then fix the threshold at its 128 KiB start)."""
    version = _glibc_version()
    return MMAP_THRESHOLD if version is not None and version >= (2, 35) else _OLD_GLIBC_LIMIT


def keep_freed_memory() -> bool:
    """Set this process's malloc thresholds (:data:`MMAP_THRESHOLD`, :data:`TRIM_THRESHOLD`) with glibc's
    ``mallopt``, unless the user set either through the environment (:data:`MALLOC_ENV`'s names), which is kept.
    Returns whether the thresholds are now fixed ones (``False`` off glibc, where nothing is changed)."""
    if not _glibc():
        return False
    if any(name in os.environ for name in MALLOC_ENV):
        return True  # the user's own setting, read by glibc at start-up
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    if not mallopt(_M_MMAP_THRESHOLD, _mmap_threshold()) and not mallopt(_M_MMAP_THRESHOLD, _OLD_GLIBC_LIMIT):
        return False
    return bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))


def malloc_env() -> dict[str, str]:
    """:data:`MALLOC_ENV` for a worker process about to start, less any name the user already set (theirs is
    inherited as it is); empty off glibc.  Before glibc 2.35 the mmap threshold is the 32 MiB that release accepts,
    as :func:`keep_freed_memory` sets it in the running process."""
    if not _glibc() or any(name in os.environ for name in MALLOC_ENV):
        return {}
    return {**MALLOC_ENV, "MALLOC_MMAP_THRESHOLD_": str(_mmap_threshold())}
