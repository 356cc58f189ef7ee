"""The plugin host: discover entry points, validate them, and index what they provide.

Build one with :func:`load_host`; nothing is loaded at import time.  Built-in and third-party plugins
arrive the same way, through the entry-point group ``workbench``.
"""

from __future__ import annotations

import difflib
import os
import traceback
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any, Iterable, Mapping

import numpy as np
import pluggy

from . import frames as _frames
from . import hookspecs
from .frames import Frame
from .params import check_value
from .specs import (CAPABILITIES, BenchmarkSpec, ClutterGeneratorSpec, ClutterRemoverSpec, FilterSpec, MotionModelSpec,
                    RecipeSpec, SensorSpec)
from .specs import TrackerSpec
from .types import InputError

__all__ = ["PluginInfo", "PluginHost", "load_host", "blocked_from_env", "UnknownComponent", "BUILTIN_DISTRIBUTION"]

BLOCK_ENV = "WORKBENCH_BLOCK"

#: The distribution whose components' names are reserved: a third-party component that reuses one is not
#: registered (the built-in keeps its name; a warning names both distributions).
BUILTIN_DISTRIBUTION = "workbench"

#: hook name -> (kind label, spec type, attribute used as the unique name)
KINDS: dict[str, tuple[str, type, str]] = {
    "workbench_filters": ("filter", FilterSpec, "name"),
    "workbench_sensors": ("sensor", SensorSpec, "name"),
    "workbench_motion_models": ("motion model", MotionModelSpec, "name"),
    "workbench_trackers": ("tracker", TrackerSpec, "name"),
    "workbench_frames": ("frame", Frame, "name"),
    "workbench_clutter_generators": ("clutter generator", ClutterGeneratorSpec, "name"),
    "workbench_clutter_removers": ("clutter remover", ClutterRemoverSpec, "name"),
    "workbench_report_recipes": ("recipe", RecipeSpec, "paper"),
    "workbench_benchmarks": ("benchmark", BenchmarkSpec, "group"),
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
    warnings: tuple[str, ...] = ()  # components not registered (a name another plugin holds), and why


@dataclass(frozen=True)
class PluginHost:
    """The loaded plugins and their components, indexed by name."""

    plugins: tuple[PluginInfo, ...]
    components: Mapping[str, Mapping[str, Any]]  # hook name -> component name -> spec
    owner: Mapping[tuple[str, str], str] = field(default_factory=dict)  # (hook, name) -> plugin name
    manager: pluggy.PluginManager | None = None
    #: (kind, name) -> why a component a loaded plugin would provide is missing (an optional dependency that is
    #: not installed): asking for it by name gives that reason instead of "not installed"
    unavailable: Mapping[tuple[str, str], str] = field(default_factory=dict)

    def _get(self, hook: str, name: str):
        table = self.components[hook]
        if name not in table:
            kind = KINDS[hook][0]
            known = ", ".join(sorted(table)) or "none"
            reason = self.unavailable.get((kind, name))
            if reason:
                raise UnknownComponent(f"the {kind} {name!r} {reason}")
            others = [KINDS[h][0] for h, t in self.components.items() if h != hook and name in t]
            if others:
                raise UnknownComponent(f"{name!r} is a {' and a '.join(others)}, not a {kind} "
                                       f"(installed {kind}s: {known})")
            hint = ""
            broken = [p for p in self.plugins if p.status != "ok"]
            if broken:
                hint = "; not loaded: " + ", ".join(f"{p.name} ({p.status})" for p in broken)
            raise UnknownComponent(f"no {kind} named {name!r} is installed (installed: {known}{hint})")
        return table[name]

    def filter(self, name: str) -> FilterSpec:
        """The installed filter ``name``, or a configured one: ``"sir(particles=2000)"`` is the ``sir`` filter
        configured with 2,000 particles (checked against its declared parameters) and named by that label."""
        if "(" in name:
            from .params import parse_reference

            base, values = parse_reference(name, "filter")
            spec = self._get("workbench_filters", base)
            return spec.configure(name=name, **values) if values else spec
        return self._get("workbench_filters", name)

    def sensor(self, name: str) -> SensorSpec:
        return self._get("workbench_sensors", name)

    def motion_model_spec(self, name: str) -> MotionModelSpec:
        """The installed motion model ``name``, or a configured one: ``"ct-rate(sigma_omega=0.01)"`` is ``ct-rate``
        with that value (checked against its declared parameters: type, unit, range)."""
        if "(" in name:
            from .params import parse_reference

            base, values = parse_reference(name, "motion model")
            return self._get("workbench_motion_models", base).configure(**values)
        return self._get("workbench_motion_models", name)

    def motion_model(self, name: str, dt: float = 1.0, **params):
        """The :class:`~workbench.models.MotionModel` built by the installed motion model ``name`` (a name or a
        reference ``"name(key=value, ...)"``) over steps of ``dt`` seconds, with ``params`` set (checked, SI)."""
        return self.motion_model_spec(name).model(dt, **params)

    def frame(self, name: str) -> Frame:
        """The measurement frame ``name``: a built-in one (:data:`workbench.frames.BUILTIN_FRAMES`) or one a loaded
        plugin adds (``workbench_frames``)."""
        if name in _frames.BUILTIN_FRAMES:
            return _frames.BUILTIN_FRAMES[name]
        if name not in self.components["workbench_frames"]:
            known = ", ".join([*_frames.BUILTIN_FRAMES, *sorted(self.components["workbench_frames"])])
            raise UnknownComponent(f"no measurement frame named {name!r} is known (frames: {known})")
        return self.components["workbench_frames"][name]

    @property
    def frames(self) -> Mapping[str, Frame]:
        """Every measurement frame this host knows: the built-ins, then those its plugins add."""
        return {**_frames.BUILTIN_FRAMES, **self.components["workbench_frames"]}

    def tracker(self, name: str) -> TrackerSpec:
        """The installed tracker ``name``, or a configured one: ``"gnn(gate_probability=0.95)"`` is ``gnn`` with
        that value (checked against its declared parameters) and named by that label."""
        if "(" in name:
            from .params import parse_reference

            base, values = parse_reference(name, "tracker")
            spec = self._get("workbench_trackers", base)
            return spec.configure(name=name, **values) if values else spec
        return self._get("workbench_trackers", name)

    @property
    def trackers(self) -> Mapping[str, TrackerSpec]:
        return self.components["workbench_trackers"]

    def clutter_generator(self, name: str) -> ClutterGeneratorSpec:
        return self._get("workbench_clutter_generators", name)

    def clutter_remover(self, name: str) -> ClutterRemoverSpec:
        return self._get("workbench_clutter_removers", name)

    def recipe(self, paper: str) -> RecipeSpec:
        return self._get("workbench_report_recipes", paper)

    def benchmark(self, group: str) -> BenchmarkSpec:
        return self._get("workbench_benchmarks", group)

    def component(self, kind: str, name: str):
        """Any component by its kind label (``"filter"``, ``"sensor"``, ``"clutter generator"``...) and name."""
        hooks = [h for h, (label, _, _) in KINDS.items() if label == kind]
        if not hooks:
            raise UnknownComponent(f"unknown component kind {kind!r} (kinds: {', '.join(k for k, _, _ in KINDS.values())})")
        return self._get(hooks[0], name)

    def find(self, name: str) -> list[tuple[str, Any]]:
        """Every component called ``name``, whatever its kind: ``[(kind, spec), ...]``; a configured filter label
        (``"sir(particles=300)"``) is that filter, configured (:meth:`filter`), and a configured motion model
        (``"ct-rate(sigma_omega=0.01)"``) that model, configured (:meth:`motion_model_spec`)."""
        if "(" in name:
            from .params import parse_reference

            base, _ = parse_reference(name, "component")
            if base in self.components["workbench_motion_models"] and base not in self.filters:
                return [("motion model", self.motion_model_spec(name))]
            if base in self.components["workbench_trackers"] and base not in self.filters:
                return [("tracker", self.tracker(name))]
            return [("filter", self.filter(name))]
        return [(KINDS[h][0], table[name]) for h, table in self.components.items() if name in table]

    @property
    def filters(self) -> Mapping[str, FilterSpec]:
        return self.components["workbench_filters"]

    @property
    def motion_models(self) -> Mapping[str, MotionModelSpec]:
        return self.components["workbench_motion_models"]

    @property
    def recipes(self) -> Mapping[str, RecipeSpec]:
        return self.components["workbench_report_recipes"]

    @property
    def benchmarks(self) -> Mapping[str, BenchmarkSpec]:
        return self.components["workbench_benchmarks"]

    @property
    def warnings(self) -> tuple[str, ...]:
        """Every plugin's warnings (e.g. a component name that another distribution holds)."""
        return tuple(w for p in self.plugins for w in p.warnings)

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
    block : iterable of str
        Names of plugins (entry-point names) not to load; ``WORKBENCH_BLOCK`` adds to these.
    entry_points : iterable of importlib.metadata.EntryPoint or None
        The entry points to load (default: the installed group ``workbench``).
    extra_plugins : iterable of (str, object)
        ``(name, module_or_object)`` pairs registered directly (tests use this).

    Returns
    -------
    PluginHost
        The host, with every plugin's components indexed and each plugin's :class:`PluginInfo` status.

    Notes
    -----
    A plugin that fails to import, implements an unknown hook, raises from a hook, returns something
    other than a list of the right specs, or declares parameters its own values fail is marked ``broken`` with a
    message naming it and its distribution; a component whose name another plugin already holds is not
    registered, with a warning naming both distributions (built-in names are reserved); everything else keeps
    working.
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
    owner_dist: dict[tuple[str, str], str] = {}
    unavailable: dict[tuple[str, str], str] = {}
    # the built-in distribution registers first: its names are reserved (see BUILTIN_DISTRIBUTION)
    loaded.sort(key=lambda item: (item[3] != BUILTIN_DISTRIBUTION, item[0]))
    for name, obj, module, dist, ver in loaded:
        who = f"plugin {name!r} ({module}, distribution {dist} {ver})"
        try:
            pm.register(obj, name=name)
        except Exception as exc:  # pluggy validates hook signatures against the specs here
            infos.append(PluginInfo(name, module, dist, ver, "broken", f"invalid hook implementation: {exc}"))
            continue
        problem = ""
        warnings: list[str] = []
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
                    if not isinstance(comp, str) or not comp or any(c in comp for c in "/\\\0") or comp != comp.strip():
                        problem = (f"hook {caller.name} returned a {spec_type.__name__} without a valid {key} "
                                   f"(a non-empty name without slashes or surrounding spaces), got {comp!r}")
                        break
                    if any(h == caller.name and c == comp for h, c, _ in provided):
                        problem = f"{kind} name {comp!r} is provided twice by this plugin"
                        break
                    declared = _declaration_problem(item)
                    if declared:
                        problem = f"{kind} {comp!r}: {declared}"
                        break
                    taken = owner.get((caller.name, comp))
                    if caller.name == "workbench_frames":  # a plugin's sensors rely on its frame: never dropped
                        clash = (f"frame {comp!r} is already provided by plugin {taken!r} (distribution "
                                 f"{owner_dist[(caller.name, comp)]}); frames are never shadowed: rename one"
                                 if taken is not None else _frames.registration_problem(item, who))
                        if clash:
                            problem = clash
                            break
                    if taken is not None:
                        holder = owner_dist[(caller.name, comp)]
                        rule = ("built-in names are reserved" if holder == BUILTIN_DISTRIBUTION
                                else "the first plugin in name order keeps it")
                        warnings.append(f"{kind} {comp!r} of distribution {dist} is not registered: the name is "
                                        f"already provided by plugin {taken!r} (distribution {holder}); {rule}. "
                                        f"Rename it in {dist} to use it")
                        continue
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
            owner_dist[(hook, comp)] = dist
        infos.append(PluginInfo(name, module, dist, ver, "ok", "",
                                tuple((KINDS[h][0], c) for h, c, _ in provided), tuple(warnings)))
        for key, why in _unavailable_of(obj):
            unavailable.setdefault(key, why)
    # a filter may serve only motion models some plugin provides; known once every plugin has registered
    why_by_plugin: dict[str, list[str]] = {}
    for comp, why in _filters_serving_unknown_models(components).items():
        why_by_plugin.setdefault(owner[("workbench_filters", comp)], []).append(why)
    for plugin_name, whys in why_by_plugin.items():
        for key in [k for k, v in owner.items() if v == plugin_name]:
            components[key[0]].pop(key[1], None)
            owner.pop(key)
        i = next(i for i, p in enumerate(infos) if p.name == plugin_name)
        info = infos[i]
        pm.unregister(name=plugin_name)
        infos[i] = PluginInfo(info.name, info.module, info.distribution, info.version, "broken",
                              f"plugin {info.name!r} ({info.module}, distribution {info.distribution} {info.version}): "
                              + "; ".join(whys))
    for comp, item in components["workbench_frames"].items():  # known to frames.frame() from now on
        owner_name = owner[("workbench_frames", comp)]
        info = next(p for p in infos if p.name == owner_name)
        _frames.register_frame(item, f"plugin {info.name!r} ({info.module}, distribution {info.distribution} "
                                     f"{info.version})")
    pm.check_pending()
    infos.sort(key=lambda p: p.name)
    return PluginHost(tuple(infos), components, owner, pm, unavailable)


#: A plugin module may name, in this attribute, the components it would provide but cannot here (an optional
#: dependency is missing): ``{("filter", "ss-ukf"): "needs Stone Soup: pip install ..."}``, each reason a phrase
#: that follows "the filter 'ss-ukf'".  It registers nothing for them and stays quiet; asking for one by name gives
#: its reason instead of "not installed".
UNAVAILABLE_ATTRIBUTE = "WORKBENCH_UNAVAILABLE"


def _unavailable_of(obj) -> list[tuple[tuple[str, str], str]]:
    table = getattr(obj, UNAVAILABLE_ATTRIBUTE, None)
    if not isinstance(table, Mapping):
        return []
    labels = {label for label, _, _ in KINDS.values()}
    return [((key[0], key[1]), str(why)) for key, why in table.items()
            if isinstance(key, tuple) and len(key) == 2 and key[0] in labels and isinstance(key[1], str)]


#: The functions each kind of component must provide (checked at load: a spec missing one is broken).
REQUIRED_FUNCTIONS = {FilterSpec: ("init", "predict", "update", "estimate"), SensorSpec: ("measurement_model", "simulate"),
                      MotionModelSpec: ("build",), TrackerSpec: ("run",),
                      ClutterGeneratorSpec: ("generate",), ClutterRemoverSpec: ("remove",),
                      RecipeSpec: ("tasks",), BenchmarkSpec: ("run",)}


#: The optional functions of a kind of component: ``None`` or a function (checked at load).
OPTIONAL_FUNCTIONS = {FilterSpec: ("take", "join", "step", "gate_candidates", "diagnostics")}


def _declaration_problem(spec) -> str:
    """What is wrong with a component's functions or parameter declarations, or ``""``.

    Every required function must be callable; every declared parameter needs a current value that passes its own
    check, and (when the component declares any) every value needs a declaration.
    """
    for name in REQUIRED_FUNCTIONS.get(type(spec), ()):
        if not callable(getattr(spec, name, None)):
            return f"its {name!r} is not a function (got {type(getattr(spec, name, None)).__name__})"
    for name in OPTIONAL_FUNCTIONS.get(type(spec), ()):
        fn = getattr(spec, name, None)
        if fn is not None and not callable(fn):
            return f"its optional {name!r} is neither a function nor None (got {type(fn).__name__})"
    if isinstance(spec, FilterSpec):  # a misspelt capability would silently switch kit checks off
        unknown = sorted(set(spec.capabilities) - set(CAPABILITIES))
        if unknown:
            close = {c: difflib.get_close_matches(c, sorted(CAPABILITIES), n=1) for c in unknown}
            hints = "".join(f"; {c!r}: did you mean {m[0]!r}?" for c, m in close.items() if m)
            return (f"unknown capabilities {unknown} (known: {', '.join(sorted(CAPABILITIES))}){hints}")
        served = spec.motion_models
        if not isinstance(served, tuple) or not all(isinstance(m, str) and m.strip() == m and m for m in served):
            return f"motion_models must be a tuple of motion-model names, got {served!r}"
    if isinstance(spec, TrackerSpec):
        unknown = sorted(set(spec.capabilities) - set(TrackerSpec.CAPABILITIES))
        if unknown:
            return f"unknown capabilities {unknown} (known: {', '.join(sorted(TrackerSpec.CAPABILITIES))})"
    parameters = getattr(spec, "parameters", None)
    problem = _parameters_problem(spec, parameters) if parameters else ""
    if problem or not isinstance(spec, MotionModelSpec):
        return problem
    return _motion_model_problem(spec)


def _motion_model_problem(spec: MotionModelSpec) -> str:
    """What is wrong with a motion model's declarations: it must build a MotionModel with its own values (over
    1 s), and its ``dims`` and example state must fit that model's state."""
    from .models import MotionModel

    try:
        model = spec.build(1.0)
    except Exception as exc:  # noqa: BLE001 - any failure to build with its own values is the finding
        return f"building it with its own parameter values over 1 s raised {_short_error(exc)}"
    if not isinstance(model, MotionModel):
        return f"its build function returned a {type(model).__name__}, not a MotionModel"
    n = model.dim
    if spec.dims is not None and (isinstance(spec.dims, bool) or not isinstance(spec.dims, int)
                                  or not 1 <= spec.dims <= n):
        return f"dims must be a whole number of position axes from 1 to the state dimension {n}, got {spec.dims!r}"
    state, std = tuple(spec.example_state), tuple(spec.example_std)
    if state or std:
        if len(state) != n or len(std) != n:
            return (f"example_state and example_std must each give the {n} components of its state "
                    f"({', '.join(model.state_names) or 'unnamed'}), got {len(state)} and {len(std)}")
        values = np.asarray(state + std, dtype=float)
        if not np.all(np.isfinite(values)) or min(std) < 0:
            return f"example_state must be finite and example_std finite and >= 0, got {state} and {std}"
    return ""


def _filters_serving_unknown_models(components: Mapping[str, Mapping[str, Any]]) -> dict[str, str]:
    """filter name -> why it cannot be registered: a motion model it declares to serve that no plugin provides."""
    models = components["workbench_motion_models"]
    out = {}
    for name, spec in components["workbench_filters"].items():
        missing = [m for m in spec.motion_models if m not in models]
        if missing:
            out[name] = (f"filter {name!r} serves the motion model{'s' if len(missing) > 1 else ''} "
                         f"{', '.join(map(repr, missing))}, which no plugin provides (installed motion models: "
                         f"{', '.join(sorted(models)) or 'none'})")
    return out


def _parameters_problem(spec, parameters) -> str:
    params = dict(getattr(spec, "params", {}) or {})
    names = [p.name for p in parameters]
    if len(set(names)) != len(names):
        return f"parameter declared twice: {sorted({n for n in names if names.count(n) > 1})}"
    missing = [n for n in names if n not in params]
    extra = [k for k in params if k not in names]
    if missing or extra:
        return (f"params and parameter declarations disagree (no value for {missing}, undeclared {extra})")
    for p in parameters:
        try:
            check_value(p, params[p.name], f"parameter {p.name}")
        except InputError as exc:
            return f"its value is not valid for its own declaration: {exc}"
    return ""
