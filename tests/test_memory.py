"""workbench.memory: the malloc thresholds of the workbench's own processes.

The effect is counted, not timed: minor page faults (``getrusage``) of a loop that allocates and frees three 3.2 MB
arrays per step while the process holds two more, as a particle filter's step does beside a program's data.  With
glibc's defaults nearly every page of the three blocks is faulted in again at every step (2,312 per step
on glibc 2.36, of the about 2,340 pages they span); with the thresholds fixed, none."""

import os
import subprocess
import sys
import textwrap

import pytest

from workbench import memory

GLIBC = memory._glibc()

PROBE = textwrap.dedent("""
    import resource, sys
    import numpy as np
    if sys.argv[1] == "call":
        from workbench.memory import keep_freed_memory
        assert keep_freed_memory()

    def step():
        a = np.ones(400_000); b = np.ones(400_000); c = a + b  # three 3.2 MB blocks, freed at the return
        return float(c[0])

    for _ in range(5):
        step()
    held = [np.ones(400_000), np.ones(400_000)]  # what a program holds beside the loop
    for _ in range(5):
        step()
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(50):
        step()
    print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0) / 50)
""")

PAGES_PER_STEP = 3 * 400_000 * 8 // 4096


def _faults_per_step(how: str, env: dict | None = None) -> float:
    base = {k: v for k, v in os.environ.items() if k not in memory.MALLOC_ENV}
    out = subprocess.run([sys.executable, "-c", PROBE, how], capture_output=True, text=True, check=True,
                         env={**base, **(env or {})})
    return float(out.stdout.strip())


@pytest.mark.skipif(not GLIBC, reason="the thresholds are glibc's (nothing is changed elsewhere)")
def test_fixed_thresholds_stop_the_page_faults_of_a_step_that_reallocates():
    default = _faults_per_step("default")
    called = _faults_per_step("call")  # keep_freed_memory() in the running process (the command line)
    started = _faults_per_step("default", memory.MALLOC_ENV)  # the environment of a new process (the workers)
    assert called < 0.02 * PAGES_PER_STEP and started < 0.02 * PAGES_PER_STEP, (default, called, started)
    # what it saves here: glibc's defaults fault the blocks in again (where they do; the assertion above is the
    # one that holds everywhere)
    print(f"faults per step: defaults {default}, mallopt {called}, environment {started}")


@pytest.mark.skipif(not GLIBC, reason="glibc only")
def test_a_users_own_malloc_setting_is_kept(monkeypatch):
    calls = []
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "12345")
    monkeypatch.setattr("ctypes.CDLL", lambda *a, **k: calls.append(a) or pytest.fail("mallopt called"))
    assert memory.keep_freed_memory() is True and not calls
    assert memory.malloc_env() == {}
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_")
    for name in memory.MALLOC_ENV:
        monkeypatch.delenv(name, raising=False)
    assert memory.malloc_env() == memory.MALLOC_ENV
    assert memory.MALLOC_ENV == {"MALLOC_MMAP_THRESHOLD_": str(256 << 20), "MALLOC_TRIM_THRESHOLD_": str(512 << 20)}


def test_nothing_is_changed_off_glibc(monkeypatch):
    monkeypatch.setattr(memory.os, "confstr", lambda name: None)  # musl: no glibc version
    monkeypatch.setattr("ctypes.CDLL", lambda *a, **k: pytest.fail("a C library was loaded"))
    assert memory.keep_freed_memory() is False and memory.malloc_env() == {}


@pytest.mark.parametrize("release, mmap", [("glibc 2.31", 32 << 20), ("glibc 2.34", 32 << 20),
                                           ("glibc 2.35", 256 << 20), ("glibc 2.39.9000", 256 << 20)])
def test_workers_get_the_mmap_threshold_their_glibc_accepts(monkeypatch, release, mmap):
    """Before 2.35 glibc ignores an mmap threshold above 32 MiB, and the trim threshold would then fix it at 128 KiB:
    the workers' environment gives 32 MiB there, as the running process falls back to."""
    monkeypatch.setattr(memory.os, "confstr", lambda name: release)
    for name in memory.MALLOC_ENV:
        monkeypatch.delenv(name, raising=False)
    assert memory.malloc_env() == {"MALLOC_MMAP_THRESHOLD_": str(mmap), "MALLOC_TRIM_THRESHOLD_": str(512 << 20)}
