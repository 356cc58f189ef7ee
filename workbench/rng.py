"""Explicit, reproducible random streams.

Every random draw in the workbench comes from a :class:`numpy.random.Generator` derived from one
integer seed and a *key* that names what the stream is for (a recipe, a task, a chunk of Monte Carlo
runs).  Streams for different keys are independent (``SeedSequence`` spawn keys), and a stream does
not depend on how many workers run the chunks or in which order.
"""

from __future__ import annotations

import hashlib

import numpy as np

__all__ = ["generator", "key_int", "chunk_bounds"]


def key_int(part) -> int:
    """A stable non-negative integer for one part of a stream key (ints pass through, strings hash)."""
    if isinstance(part, (int, np.integer)) and part >= 0:
        return int(part)
    digest = hashlib.sha256(str(part).encode()).digest()
    return int.from_bytes(digest[:8], "little")


def generator(seed: int, *key) -> np.random.Generator:
    """The generator for ``seed`` and a key such as ``("monte-carlo", "L2", "chunk", 3)``."""
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
