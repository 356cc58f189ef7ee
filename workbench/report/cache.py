"""A result cache for report tasks: one NPZ file per finished task, written atomically.

The key covers the recipe, the task key, its parameters, the seed and the code version, so a
re-run reuses every finished task, and a changed parameter (or changed code) recomputes only what it
touches.  An interrupted report loses at most the task that was running.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any, Mapping

import numpy as np

__all__ = ["task_key", "code_version", "save_arrays", "load_arrays", "write_text_atomic", "TaskCache"]


def _canonical(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _canonical(v) for k, v in sorted(obj.items(), key=lambda kv: str(kv[0]))}
    if isinstance(obj, (list, tuple)):
        return [_canonical(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    raise TypeError(f"task parameters must be JSON-serialisable; got {type(obj).__name__}: {obj!r}")


def task_key(paper: str, key: str, params: Mapping[str, Any], seed: int, version: str) -> str:
    """A stable hash of everything a task's result depends on."""
    blob = json.dumps({"paper": paper, "key": key, "params": _canonical(params), "seed": seed,
                       "version": version}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


@lru_cache(maxsize=None)
def _source_digest(roots: tuple[str, ...]) -> str:
    h = hashlib.sha256()
    for root in roots:
        base = Path(root)
        files = [base] if base.is_file() else sorted(p for p in base.rglob("*.py") if "tests" not in p.parts)
        for path in files:
            h.update(path.name.encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _source_root(module_file: str) -> str:
    """A module's package folder, or the file itself for a top-level single-file module."""
    path = Path(module_file)
    return str(path.parent) if (path.parent / "__init__.py").exists() else str(path)


def code_version(module_files: tuple[str, ...] = ()) -> str:
    """The workbench version plus a digest of the source of the modules ``module_files`` belong to.

    Each file counts with its whole package (or alone, for a single-file module), so editing the core,
    a recipe or a plugin's source invalidates the cached results that depend on it.
    """
    import workbench

    roots = {str(Path(workbench.__file__).parent)} | {_source_root(f) for f in module_files if f}
    return f"{workbench.__version__}+{_source_digest(tuple(sorted(roots)))}"


def save_arrays(path: Path, arrays: Mapping[str, Any]) -> None:
    """Write ``arrays`` to ``path`` (NPZ) atomically: a reader sees the old file or the whole new one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    clean = {}
    for name, value in arrays.items():
        arr = np.asarray(value)
        if arr.dtype == object:
            raise TypeError(f"result {name!r} is not a plain array (dtype=object); return numbers or strings")
        clean[name] = arr
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp.npz")
    os.close(fd)
    try:
        np.savez_compressed(tmp, **clean)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically: a temporary file in the same folder, then ``os.replace``.

    A reader (or a crash) sees the old file or the whole new one, never a part.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.chmod(tmp, 0o644)  # mkstemp makes the file private; a report is for reading
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def load_arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return {name: data[name] for name in data.files}


class TaskCache:
    """Finished task results under ``root/<paper>/<task>-<hash>.npz``."""

    def __init__(self, root: Path):
        self.root = Path(root)

    def path(self, paper: str, key: str, digest: str) -> Path:
        safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in key)
        return self.root / f"paper{paper}" / f"{safe}-{digest[:16]}.npz"

    def get(self, paper: str, key: str, digest: str) -> dict[str, np.ndarray] | None:
        path = self.path(paper, key, digest)
        if not path.exists():
            return None
        try:
            return load_arrays(path)
        except Exception:  # a truncated file from a crash mid-write of an older version: recompute
            return None

    def put(self, paper: str, key: str, digest: str, arrays: Mapping[str, Any]) -> Path:
        path = self.path(paper, key, digest)
        save_arrays(path, arrays)
        return path


def distribution_versions(names: tuple[str, ...] = ("numpy", "scipy", "taichi", "matplotlib", "pluggy",
                                                    "workbench")) -> dict[str, str]:
    out = {}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out
