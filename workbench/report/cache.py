"""A result cache for report tasks: one NPZ file per finished task, written atomically.

The key covers the recipe, the task key, its parameters, the seed, the size, the arch and the code version
of the core and of the recipe's package; the entry also records the components (filters, sensors, clutter
plugins) the task actually asked the host for, with a fingerprint of each (its plugin, distribution version,
the source of the modules its functions come from, its parameters).  A re-run reuses every finished task
whose components are unchanged, so installing, removing or blocking a plugin that a task does not use keeps
its result, and a changed parameter (or changed code) recomputes only what it touches.  An interrupted report
loses at most the task that was running; an entry that cannot be read is set aside (``*.corrupt``), named and
recomputed.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import sys
import tempfile
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

__all__ = ["task_key", "code_version", "save_arrays", "load_arrays", "write_text_atomic", "TaskCache",
           "CacheEntryUnreadable", "component_fingerprint", "components_digest", "DEPS_ARRAY"]

#: The array, inside a cache entry, that records the components the task used and their fingerprints (JSON).
DEPS_ARRAY = "__workbench_components__"


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


def task_key(paper: str, key: str, params: Mapping[str, Any], seed: int, version: str, size: str | None = None,
             arch: str | None = None) -> str:
    """A stable hash of what a task's result depends on, apart from the components it uses (those are recorded
    in the entry and checked on reading: :meth:`TaskCache.get`)."""
    fields = {"paper": paper, "key": key, "params": _canonical(params), "seed": seed, "version": version}
    if size is not None:
        fields["size"] = size
    if arch is not None:
        fields["arch"] = arch
    blob = json.dumps(fields, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


@lru_cache(maxsize=None)
def _source_digest(roots: tuple[str, ...]) -> str:
    h = hashlib.sha256()
    for root in roots:
        base = Path(root)
        files = [base] if base.is_file() else sorted(p for p in base.rglob("*.py")
                                                      if "tests" not in p.relative_to(base).parts)
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


def _module_files(obj: Any) -> set[str]:
    """The source files of the modules that the callables among ``obj``'s fields come from."""
    values = [getattr(obj, f.name) for f in dataclasses.fields(obj)] if dataclasses.is_dataclass(obj) else [obj]
    out = set()
    for value in values:
        module = getattr(value, "__module__", None) if callable(value) else None
        path = getattr(sys.modules.get(module or ""), "__file__", None)
        if path:
            out.add(path)
    return out


def component_fingerprint(host, hook: str, name: str) -> str:
    """A fingerprint of the component ``name`` of ``host`` (hook ``hook``; ``"*"`` is the whole table).

    It covers the component's label (a configured filter's label carries its values), its parameters, the
    plugin and distribution (with its version) that registered it, and the source of the modules its functions
    and its plugin come from; ``"absent"`` when the host has no such component.
    """
    table = host.components.get(hook, {})
    if name == "*":
        parts = [f"{n}={component_fingerprint(host, hook, n)}" for n in sorted(table)]
        return hashlib.sha256("|".join(parts).encode()).hexdigest()[:16]
    base = name.split("(", 1)[0] if "(" in name else name
    if base not in table:
        return "absent"
    spec = table[base]
    if name != base:
        try:
            spec = host.filter(name)
        except Exception:  # noqa: BLE001 - a label the host no longer accepts is a different component
            return "invalid"
    files = _module_files(spec)
    plugin = ("-", "-", "-")
    owner = getattr(host, "owner", {}).get((hook, base))
    info = next((p for p in host.plugins if p.name == owner), None) if owner else None
    if info is not None:
        plugin = (info.name, info.distribution, info.version)
        path = getattr(sys.modules.get(info.module.split(":")[0]), "__file__", None)
        if path:
            files.add(path)
    try:
        params = _canonical(dict(getattr(spec, "params", {}) or {}))
    except TypeError:
        params = repr(sorted(dict(spec.params).items(), key=lambda kv: str(kv[0])))
    blob = json.dumps({"name": name, "plugin": plugin, "params": params,
                       "source": code_version(tuple(sorted(files)))}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def components_digest(host, used: "Iterable[tuple[str, str]]") -> dict[str, str]:
    """``{"hook:name": fingerprint}`` of every component in ``used`` (pairs ``(hook, name)``)."""
    return {f"{hook}:{name}": component_fingerprint(host, hook, name) for hook, name in sorted(set(used))}


class CacheEntryUnreadable(Exception):
    """A cache entry that could not be read; it was moved aside to ``moved_to`` (or could not be moved)."""

    def __init__(self, path: Path, moved_to: Path | None, reason: str):
        self.path, self.moved_to, self.reason = Path(path), moved_to, reason
        where = f"set aside as {moved_to.name}" if moved_to is not None else "could not be set aside"
        super().__init__(f"cache entry {self.path} could not be read ({reason}); {where}; recomputed")


class TaskCache:
    """Finished task results under ``root/<paper>/<task>-<hash>.npz``.

    Each entry holds the task's arrays and :data:`DEPS_ARRAY`, the components the task used with their
    fingerprints; :meth:`get` returns the entry only while those fingerprints still hold for the host given.
    """

    def __init__(self, root: Path):
        self.root = Path(root)

    def path(self, paper: str, key: str, digest: str) -> Path:
        safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in key)
        return self.root / f"paper{paper}" / f"{safe}-{digest[:16]}.npz"

    def _set_aside(self, path: Path, reason: str) -> CacheEntryUnreadable:
        target = path.with_name(path.name + ".corrupt")
        n = 1
        while target.exists():
            n += 1
            target = path.with_name(f"{path.name}.{n}.corrupt")
        try:
            os.replace(path, target)
        except OSError:
            target = None
        return CacheEntryUnreadable(path, target, reason)

    def get(self, paper: str, key: str, digest: str, host=None) -> dict[str, np.ndarray] | None:
        """The cached arrays, or ``None`` when there is no entry or a component it used has changed.

        Raises
        ------
        CacheEntryUnreadable
            When the entry exists but cannot be read: it has been moved aside (``*.corrupt``) first, so the
            caller recomputes the task and names the entry.
        """
        path = self.path(paper, key, digest)
        if not path.exists():
            return None
        try:
            arrays = load_arrays(path)
            deps = json.loads(str(arrays.pop(DEPS_ARRAY))) if DEPS_ARRAY in arrays else None
            if deps is not None and not isinstance(deps, dict):
                raise ValueError(f"{DEPS_ARRAY} is not a mapping")
        except Exception as exc:  # noqa: BLE001 - truncated, overwritten, not an NPZ: set aside and recompute
            raise self._set_aside(path, f"{type(exc).__name__}: {exc}") from None
        if deps is None:  # written without the components it used: unknown, so recompute
            return None
        if host is not None:
            for ident, fingerprint in deps.items():
                hook, _, name = ident.partition(":")
                if component_fingerprint(host, hook, name) != fingerprint:
                    return None
        return arrays

    def put(self, paper: str, key: str, digest: str, arrays: Mapping[str, Any],
            components: Mapping[str, str] | None = None) -> Path:
        """Save ``arrays`` with the fingerprints of the ``components`` the task used (see :meth:`get`)."""
        path = self.path(paper, key, digest)
        payload = dict(arrays)
        payload[DEPS_ARRAY] = np.array(json.dumps(dict(components or {}), sort_keys=True))
        save_arrays(path, payload)
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
