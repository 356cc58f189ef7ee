"""Explicit, reproducible random streams.

Every random draw in the workbench comes from a :class:`numpy.random.Generator` derived from one
integer seed and a *key* that names what the stream is for (a recipe, a task, a chunk of Monte Carlo
runs).  Streams for different keys are independent (``SeedSequence`` spawn keys), and a stream does
not depend on how many workers run the chunks or in which order.
"""

from __future__ import annotations

import functools
import hashlib
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

__all__ = ["generator", "key_int", "chunk_bounds", "standard_normal_blocks", "draw_threads", "NORMAL_BLOCKS"]

#: How many row blocks :func:`standard_normal_blocks` splits a large draw into (a constant: the numbers
#: depend on it, so it must not follow the machine).
NORMAL_BLOCKS = 8
#: Below this many numbers a draw is not split (the children and threads cost more than they save).
NORMAL_SPLIT_MIN = 1 << 16


def key_int(part) -> int:
    """A stable non-negative integer for one part of a stream key (ints pass through, strings hash)."""
    if isinstance(part, (int, np.integer)) and part >= 0:
        return int(part)
    digest = hashlib.sha256(str(part).encode()).digest()
    return int.from_bytes(digest[:8], "little")


def generator(seed: int, *key) -> np.random.Generator:
    """The generator for ``seed`` and a key such as ``("paper003", "L2", "chunk", 3)``."""
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    seq = np.random.SeedSequence(int(seed), spawn_key=tuple(key_int(k) for k in key))
    return np.random.Generator(np.random.PCG64(seq))


def chunk_bounds(runs: int, chunk: int) -> list[tuple[int, int]]:
    """Split ``runs`` Monte Carlo runs into fixed-size chunks ``[(start, stop), ...]``.

    The chunking depends only on ``runs`` and ``chunk``, never on the number of workers, so results
    built from per-chunk streams are identical however the chunks are scheduled.
    """
    if runs < 0 or chunk < 1:
        raise ValueError(f"need runs >= 0 and chunk >= 1, got runs={runs}, chunk={chunk}")
    return [(s, min(s + chunk, runs)) for s in range(0, runs, chunk)]


def draw_threads() -> int:
    """Threads for :func:`standard_normal_blocks`: ``WORKBENCH_THREADS`` if set, else ``NUMBA_NUM_THREADS``
    (set to 1 on single-threaded Dask workers), else the CPUs this process may use."""
    for name in ("WORKBENCH_THREADS", "NUMBA_NUM_THREADS"):
        value = os.environ.get(name, "").strip()
        if value:
            try:
                return max(1, int(value))
            except ValueError:
                raise ValueError(f"{name} must be a positive integer, got {value!r}") from None
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


@functools.cache
def _pool(threads: int) -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=threads, thread_name_prefix="workbench-draw")


def standard_normal_blocks(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Standard normals of ``shape``, drawn on several threads with numbers that never depend on them.

    A draw of fewer than :data:`NORMAL_SPLIT_MIN` numbers, or with one row, is ``rng.standard_normal
    (shape)``.  A larger one splits the first axis into ``min(rows, NORMAL_BLOCKS)`` fixed row blocks;
    block ``k`` is filled by an SFC64 generator seeded with the ``k``-th child of ``rng``'s seed
    sequence (``SeedSequence.spawn``: independent streams), on a pool of :func:`draw_threads` threads
    (NumPy releases the GIL while it draws).  The result depends on ``rng``'s state and ``shape`` only, so the same seed gives the same
    numbers on any machine and with any number of threads; ``rng`` itself is not advanced (its seed
    sequence counts the children it spawned, so the next call gets new ones).

    Shapes
    ------
    shape : (rows, ...)
    returns : shape, float64
    """
    shape = tuple(int(s) for s in shape)
    total = int(np.prod(shape))
    if not shape or shape[0] <= 1 or total < NORMAL_SPLIT_MIN:
        return rng.standard_normal(shape)
    blocks = min(shape[0], NORMAL_BLOCKS)
    # SFC64 children: the fastest of NumPy's bit generators here (ziggurat normals about 1.4x PCG64's)
    children = [np.random.Generator(np.random.SFC64(seq)) for seq in rng.bit_generator.seed_seq.spawn(blocks)]
    edges = np.linspace(0, shape[0], blocks + 1).astype(int)
    out = np.empty(shape)

    def fill(k: int) -> None:
        children[k].standard_normal(out=out[edges[k]:edges[k + 1]])

    threads = min(draw_threads(), blocks)
    if threads == 1:
        for k in range(blocks):
            fill(k)
    else:
        list(_pool(threads).map(fill, range(blocks)))
    return out
