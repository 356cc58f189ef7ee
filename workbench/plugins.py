"""The plugin host: discover entry points, validate them, and index what they provide.

Build one with :func:`load_host`; nothing is loaded at import time.  Built-in and third-party plugins
arrive the same way, through the entry-point group ``workbench``.
"""

from __future__ import annotations

import os
import traceback
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any, Iterable, Mapping

import pluggy

from . import hookspecs
from .specs import ClutterGeneratorSpec, ClutterRemoverSpec, FilterSpec, RecipeSpec, SensorSpec

__all__ = ["PluginInfo", "PluginHost", "load_host", "blocked_from_env", "UnknownComponent"]

BLOCK_ENV = "WORKBENCH_BLOCK"

#: hook name -> (kind label, spec type, attribute used as the unique name)
KINDS: dict[str, tuple[str, type, str]] = {
    "workbench_filters": ("filter", FilterSpec, "name"),
    "workbench_sensors": ("sensor", SensorSpec, "name"),
    "workbench_clutter_generators": ("clutter generator", ClutterGeneratorSpec, "name"),
    "workbench_clutter_removers": ("clutter remover", ClutterRemoverSpec, "name"),
    "workbench_report_recipes": ("recipe", RecipeSpec, "paper"),
}


class UnknownComponent(KeyError):
    """A filter, sensor, clutter plugin or recipe that is not installed (or is blocked/broken)."""

    def __str__(self) -> str:  # KeyError quotes its message; show it plainly
        return str(self.args[0])


@dataclass(frozen=True)
class PluginInfo:
    """One entry point and what became of it."""

    name: str
    module: str
    distribution: str
    version: str
    status: str  # "ok", "broken" or "blocked"
    error: str = ""
    provides: tuple[tuple[str, str], ...] = ()  # (kind, component name)


@dataclass(frozen=True)
class PluginHost:
    """The loaded plugins and their components, indexed by name."""

    plugins: tuple[PluginInfo, ...]
    components: Mapping[str, Mapping[str, Any]]  # hook name -> component name -> spec
    owner: Mapping[tuple[str, str], str] = field(default_factory=dict)  # (hook, name) -> plugin name
    manager: pluggy.PluginManager | None = None

    def _get(self, hook: str, name: str):
        table = self.components[hook]
        if name not in table:
            kind = KINDS[hook][0]
            known = ", ".join(sorted(table)) or "none"
            hint = ""
            broken = [p for p in self.plugins if p.status != "ok"]
            if broken:
                hint = "; not loaded: " + ", ".join(f"{p.name} ({p.status})" for p in broken)
            raise UnknownComponent(f"no {kind} named {name!r} is installed (installed: {known}{hint})")
        return table[name]

    def filter(self, name: str) -> FilterSpec:
        return self._get("workbench_filters", name)

    def sensor(self, name: str) -> SensorSpec:
        return self._get("workbench_sensors", name)

    def clutter_generator(self, name: str) -> ClutterGeneratorSpec:
        return self._get("workbench_clutter_generators", name)

    def clutter_remover(self, name: str) -> ClutterRemoverSpec:
        return self._get("workbench_clutter_removers", name)

    def recipe(self, paper: str) -> RecipeSpec:
        return self._get("workbench_report_recipes", paper)

    @property
    def filters(self) -> Mapping[str, FilterSpec]:
        return self.components["workbench_filters"]

    @property
    def recipes(self) -> Mapping[str, RecipeSpec]:
        return self.components["workbench_report_recipes"]

    def plugin_of(self, hook: str, name: str) -> PluginInfo:
        plugin = self.owner[(hook, name)]
        return next(p for p in self.plugins if p.name == plugin)

    @property
    def broken(self) -> tuple[PluginInfo, ...]:
        return tuple(p for p in self.plugins if p.status == "broken")


def blocked_from_env() -> set[str]:
    """Plugin names listed in ``WORKBENCH_BLOCK`` (comma or space separated)."""
    raw = os.environ.get(BLOCK_ENV, "")
    return {part for part in raw.replace(",", " ").split() if part}


def _short_error(exc: BaseException) -> str:
    frames = traceback.extract_tb(exc.__traceback__)
    where = f" (at {frames[-1].filename}:{frames[-1].lineno})" if frames else ""
    return f"{type(exc).__name__}: {exc}{where}"


def _dist_of(ep: metadata.EntryPoint) -> tuple[str, str]:
    dist = getattr(ep, "dist", None)
    if dist is None:
        return "-", "-"
    return dist.metadata["Name"] or "-", dist.version or "-"


def load_host(block: Iterable[str] = (), entry_points: Iterable[metadata.EntryPoint] | None = None,
              extra_plugins: Iterable[tuple[str, object]] = ()) -> PluginHost:
    """Build a fresh plugin host.

    Parameters
    ----------
    block : names of plugins (entry-point names) not to load; ``WORKBENCH_BLOCK`` adds to these.
    entry_points : the entry points to load (default: the installed group ``workbench``).
    extra_plugins : ``(name, module_or_object)`` pairs registered directly (tests use this).

    A plugin that fails to import, implements an unknown hook, raises from a hook, returns something
    other than a list of the right specs, or reuses a component name already taken is marked
    ``broken`` with a message naming it and its distribution; everything else keeps working.
    """
    blocked = set(block) | blocked_from_env()
    if entry_points is None:
        entry_points = metadata.entry_points(group=hookspecs.ENTRY_POINT_GROUP)
    pm = pluggy.PluginManager(hookspecs.PROJECT)
    pm.add_hookspecs(hookspecs)

    infos: list[PluginInfo] = []
    loaded: list[tuple[str, object, str, str, str]] = []  # name, plugin, module, dist, version
    seen_names: set[str] = set()
    for ep in sorted(entry_points, key=lambda e: e.name):
        dist, ver = _dist_of(ep)
        if ep.name in seen_names:
            infos.append(PluginInfo(ep.name, ep.value, dist, ver, "broken",
                                    f"another entry point already uses the plugin name {ep.name!r}"))
            continue
        seen_names.add(ep.name)
        if ep.name in blocked:
            infos.append(PluginInfo(ep.name, ep.value, dist, ver, "blocked"))
            continue
        try:
            obj = ep.load()
        except BaseException as exc:  # noqa: BLE001 - any import failure makes the plugin broken
            if isinstance(exc, KeyboardInterrupt):
                raise
            infos.append(PluginInfo(ep.name, ep.value, dist, ver, "broken", f"import failed: {_short_error(exc)}"))
            continue
        loaded.append((ep.name, obj, ep.value, dist, ver))
    for name, obj in extra_plugins:
        if name in blocked:
            infos.append(PluginInfo(name, getattr(obj, "__name__", repr(obj)), "-", "-", "blocked"))
            continue
        loaded.append((name, obj, getattr(obj, "__name__", repr(obj)), "-", "-"))

    components: dict[str, dict[str, Any]] = {hook: {} for hook in KINDS}
    owner: dict[tuple[str, str], str] = {}
    for name, obj, module, dist, ver in loaded:
        who = f"plugin {name!r} ({module}, distribution {dist} {ver})"
        try:
            pm.register(obj, name=name)
        except Exception as exc:  # pluggy validates hook signatures against the specs here
            infos.append(PluginInfo(name, module, dist, ver, "broken", f"invalid hook implementation: {exc}"))
            continue
        problem = ""
        provided: list[tuple[str, str, Any]] = []
        for caller in pm.get_hookcallers(obj) or []:
            if not caller.has_spec():
                problem = f"implements {caller.name!r}, which is not a workbench hook " \
                          f"(known: {', '.join(sorted(KINDS))})"
                break
            kind, spec_type, key = KINDS[caller.name]
            impls = [i for i in caller.get_hookimpls() if i.plugin_name == name]
            for impl in impls:
                try:
                    result = impl.function()
                except Exception as exc:  # noqa: BLE001
                    problem = f"hook {caller.name} raised {_short_error(exc)}"
                    break
                if not isinstance(result, (list, tuple)):
                    problem = f"hook {caller.name} must return a list of {spec_type.__name__}, got {type(result).__name__}"
                    break
                for item in result:
                    if not isinstance(item, spec_type):
                        problem = (f"hook {caller.name} returned a {type(item).__name__}; "
                                   f"expected {spec_type.__name__}")
                        break
                    comp = getattr(item, key)
                    if not isinstance(comp, str) or not comp:
                        problem = f"hook {caller.name} returned a {spec_type.__name__} without a {key}"
                        break
                    taken = owner.get((caller.name, comp))
                    if taken is None and any(h == caller.name and c == comp for h, c, _ in provided):
                        taken = name
                    if taken:
                        problem = f"{kind} name {comp!r} is already provided by plugin {taken!r}"
                        break
                    provided.append((caller.name, comp, item))
                if problem:
                    break
            if problem:
                break
        if problem:
            pm.unregister(obj)
            infos.append(PluginInfo(name, module, dist, ver, "broken", f"{who}: {problem}"))
            continue
        for hook, comp, item in provided:
            components[hook][comp] = item
            owner[(hook, comp)] = name
        infos.append(PluginInfo(name, module, dist, ver, "ok", "",
                                tuple((KINDS[h][0], c) for h, c, _ in provided)))
    pm.check_pending()
    infos.sort(key=lambda p: p.name)
    return PluginHost(tuple(infos), components, owner, pm)
