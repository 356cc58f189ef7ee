"""Declared parameters: what a component can be configured with, checked where values come in.

Every component spec (filter, sensor, clutter generator or remover) declares its parameters as a tuple of
:class:`Param` (name, type, default, unit, range, one-line doc).  Values reach a component through one
checked door, :func:`check_values`, from a scenario file, the command line (``"+sir(particles=2000)"``) or
Python (``spec.configure(particles=2000)``): a wrong type, a NaN, a value out of range or a quantity of the
wrong unit (``sigma_r = "1 s"``) is refused with a message that names the component, the key and what was
expected.  Quantities may be written with units (``"10 deg"``, ``"2.5 km"``) and are converted to SI.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Sequence

from .types import InputError, memory_limit  # memory_limit: defined beside check_size, read here too
from .units import DIMENSIONS, GENERIC_LIMIT, LIMITS, SI_LABELS, parse_quantity

__all__ = ["Param", "AtLeast", "when_text", "when_example", "check_value", "check_values", "infer_params", "describe",
           "format_value", "defaults", "declared_values", "declared_factory", "declared_dataclass", "parse_reference",
           "split_list", "check_footprint", "memory_limit"]

#: The value types a parameter may declare.
TYPES = ("float", "int", "bool", "str", "vector", "float?", "vector?")


@dataclass(frozen=True)
class AtLeast:
    """A :attr:`Param.when` condition other than equality: the other parameter is at least ``value`` (e.g. a
    site's detection probability matters only where there is at least one site: ``when={"sites": AtLeast(1)}``)."""

    value: float

    def holds(self, x: Any) -> bool:
        return isinstance(x, (int, float)) and not isinstance(x, bool) and x >= self.value

    def example(self) -> float:
        """A value that meets the condition (what a kit configures to try the parameter)."""
        return self.value


def when_text(key: str, want: Any) -> str:
    """One :attr:`Param.when` condition in words: ``frame = polar``, ``sites >= 1``."""
    if isinstance(want, AtLeast):
        return f"{key} >= {format_value(want.value)}"
    return f"{key} = {format_value(want)}"


def when_example(want: Any) -> Any:
    """A value that meets the :attr:`Param.when` condition ``want``."""
    return want.example() if isinstance(want, AtLeast) else want


@dataclass(frozen=True)
class Param:
    """One declared parameter of a component.

    Attributes
    ----------
    name : str
        The keyword the component's functions take.
    default : Any
        Its default value (in SI units).
    doc : str
        One line for ``workbench plugins NAME`` and the docs.
    type : str
        ``"float"``, ``"int"``, ``"bool"``, ``"str"``, ``"vector"`` (a tuple of floats), or ``"float?"`` /
        ``"vector?"`` (the same or ``None``).
    unit : str or None
        The unit dimension of the value, one of :data:`workbench.units.DIMENSIONS`: a quantity (``"length"``,
        ``"angle"``, ``"time"``, ``"speed"``, ``"acceleration"``, ``"frequency"``, ``"decibel"``, ``"power"``,
        ``"angular_rate"``, ``"area"``, ``"inverse_volume"``, ``"angle_deg"`` for an angle held in degrees),
        ``"gate"`` (a Mahalanobis gate held as the chi-square value d^2; ``"3 sigma"`` reads as 9),
        ``"state"`` (in the SI units of the filter's state components, bare numbers only) or ``"dimensionless"``
        (a ratio, a probability, a count, a factor: bare numbers only).  ``None`` means *not declared* (a
        third-party declaration, or one inferred by :func:`infer_params`): bare numbers only.  Every built-in
        numeric parameter declares one.  Values are SI (angles in radians); a string such as ``"10 deg"`` is
        converted, and a string of another dimension (``"3 km"`` for a gate) is refused naming the units allowed.
    minimum, maximum : float or None
        Inclusive bounds of a number (of every element of a vector).  Besides these, every value is held to its
        dimension's physical limit (:data:`workbench.units.LIMITS`, e.g. 1e9 m for a length), so an extreme
        finite number (1e200, whose square overflows) is refused where it comes in.
    above : float or None
        A strict lower bound (the value must be greater).
    choices : tuple or None
        The allowed values of a ``"str"`` parameter.
    length : int or None
        The required length of a ``"vector"``.
    affects : str
        What the value of a sensor's parameter reaches (one of :attr:`AFFECTS`), which decides what a scenario
        with recorded detections does with it (``workbench run`` refuses a ``[sensor]`` key that nothing would
        use, naming the key and the recorded file):

        - ``"model"`` (the default, and the only role of other components' parameters): the measurement model
          the filters get (its function, frame, geometry or declared detection law); honoured with recorded
          detections as with simulated ones.
        - ``"noise"``: the model's noise covariance ``R`` only; honoured with recorded detections, unless the
          file gives each detection its own accuracy, which the filters use instead of ``R`` (then refused,
          naming both).
        - ``"simulation"``: only the simulated detections (a detection probability, a strength, a noise the
          filters' ``R`` does not use, the map's extent); with recorded detections the file replaces the
          simulation, so the key is refused (unless the file's reader itself uses or checks it, such as a
          carrier or a transmitter the file also declares).
    when : tuple of (name, value) pairs
        For ``"model"`` and ``"noise"``: the values of the component's other parameters under which this one
        reaches the model (all must hold; a mapping is accepted); otherwise it affects only the simulation, e.g.
        ``when={"frame": "polar"}`` for the range sigma of a polar model that a ``frame`` parameter chooses;
        a value :class:`AtLeast` asks for at least that value instead of equality.  Empty: always.
    """

    name: str
    default: Any
    doc: str
    type: str = "float"
    unit: str | None = None
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple | None = None
    length: int | None = None
    above: float | None = None
    footprint: float | None = None
    affects: str = "model"
    when: tuple = ()

    #: The roles of :attr:`affects`.
    AFFECTS = ("model", "noise", "simulation")

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f"Param {self.name!r}: type must be one of {TYPES}, got {self.type!r}")
        if self.unit is not None and self.unit not in DIMENSIONS:
            raise ValueError(f"Param {self.name!r}: unknown unit dimension {self.unit!r} (known: "
                             f"{', '.join(DIMENSIONS)})")
        if self.affects not in Param.AFFECTS:
            raise ValueError(f"Param {self.name!r}: affects must be one of {Param.AFFECTS}, got {self.affects!r}")
        when = tuple(self.when.items()) if isinstance(self.when, Mapping) else tuple(tuple(c) for c in self.when)
        if any(len(c) != 2 or not isinstance(c[0], str) or c[0] == self.name for c in when):
            raise ValueError(f"Param {self.name!r}: when must pair other parameters' names with values, got "
                             f"{self.when!r}")
        if when and self.affects == "simulation":
            raise ValueError(f"Param {self.name!r}: when applies to 'model' and 'noise' parameters; a 'simulation' "
                             f"one never reaches the model")
        object.__setattr__(self, "when", when)

    def reaches_model(self, values: Mapping[str, Any]) -> bool:
        """Whether this parameter enters the measurement model the filters get when the component's parameters
        are ``values`` (every value, defaults included): its role is ``"model"`` or ``"noise"`` and every
        condition of :attr:`when` holds."""
        return self.affects != "simulation" and not self.unmet(values)

    def unmet(self, values: Mapping[str, Any]) -> tuple[tuple[str, Any], ...]:
        """The conditions of :attr:`when` that ``values`` do not meet, as ``(name, required value)``."""
        return tuple((key, want) for key, want in self.when if not Param._same(values.get(key), want))

    @staticmethod
    def _same(value: Any, want: Any) -> bool:
        """Whether a value meets a :attr:`when` condition (``None`` only by ``None``; sequences element by
        element)."""
        if isinstance(want, AtLeast):
            return want.holds(value)
        if want is None or value is None:
            return value is None and want is None
        if isinstance(want, (list, tuple)):
            return isinstance(value, (list, tuple)) and len(value) == len(want) and all(map(Param._same, value, want))
        return bool(value == want)

    @property
    def role(self) -> str:
        """What the parameter reaches, for listings: ``""`` for a plain model parameter, else e.g.
        ``"simulation only"``, ``"model R"``, ``"model R if frame = polar"`` or ``"only if sites >= 1"``."""
        if self.affects == "model" and not self.when:
            return ""
        text = {"model": "", "noise": "model R", "simulation": "simulation only"}[self.affects]
        if self.when:
            text += (" if " if text else "only if ") + ", ".join(when_text(key, want) for key, want in self.when)
        return text

    @property
    def unit_label(self) -> str:
        """The SI unit of the value, for listings (``"m"``, ``"rad"``, ``"m/s"``...)."""
        return SI_LABELS.get(self.unit or "", "")

    @property
    def bounds(self) -> tuple[float, float]:
        """The effective closed range ``(low, high)`` of a number (of every element of a vector): the declared
        bounds within the dimension's physical limit (:data:`workbench.units.LIMITS`).  ``above`` counts as its
        (excluded) lower end."""
        limit = LIMITS.get(self.unit or "", GENERIC_LIMIT)
        low = max(v for v in (-limit, self.minimum, self.above) if v is not None)
        high = min(v for v in (limit, self.maximum) if v is not None)
        return float(low), float(high)


def _number(param: Param, value: Any, where: str, integer: bool = False) -> float | int:
    if integer:
        if isinstance(value, bool) or not isinstance(value, (int,)) and not (
                isinstance(value, float) and value.is_integer()):
            raise InputError(f"{where}: expected an integer, got {value!r}")
        number: float | int = int(value)
    else:
        number = parse_quantity(value, param.unit, where)
    if not math.isfinite(number):
        raise InputError(f"{where}: expected a finite number, got {value!r}")
    limit = LIMITS.get(param.unit or "", GENERIC_LIMIT)
    if not abs(number) <= limit:  # ints (floats are held to it by parse_quantity)
        raise InputError(f"{where}: {value!r} is beyond the physical range of this parameter (|value| <= "
                         f"{limit:g}{_unit(param)})")
    if param.above is not None and not number > param.above:
        raise InputError(f"{where}: must be > {param.above:g}{_unit(param)}, got {number:g}")
    if param.minimum is not None and number < param.minimum:
        raise InputError(f"{where}: must be >= {param.minimum:g}{_unit(param)}, got {number:g}")
    if param.maximum is not None and number > param.maximum:
        raise InputError(f"{where}: must be <= {param.maximum:g}{_unit(param)}, got {number:g}")
    return number


def _unit(param: Param) -> str:
    return f" {param.unit_label}" if param.unit_label else ""


def check_value(param: Param, value: Any, where: str) -> Any:
    """``value`` checked against ``param`` and converted to SI; :class:`InputError` naming ``where`` otherwise."""
    kind = param.type
    if kind in ("float?", "vector?") and value is None:
        return None
    if kind in ("float", "float?"):
        return float(_number(param, value, where))
    if kind == "int":
        return int(_number(param, value, where, integer=True))
    if kind == "bool":
        if not isinstance(value, bool):
            raise InputError(f"{where}: expected true or false, got {value!r}")
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise InputError(f"{where}: expected a string, got {type(value).__name__} {value!r}")
        if param.choices is not None and value not in param.choices:
            raise InputError(f"{where}: expected one of {', '.join(map(str, param.choices))}, got {value!r}")
        return value
    # vector, vector?
    if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
        raise InputError(f"{where}: expected a list of numbers, got {value!r}")
    items = list(value)
    if param.length is not None and len(items) != param.length:
        raise InputError(f"{where}: expected {param.length} values, got {len(items)}")
    return tuple(float(_number(param, v, f"{where}[{i}]")) for i, v in enumerate(items))


def check_values(params: Iterable[Param], values: Mapping[str, Any], where: str) -> dict[str, Any]:
    """Check every entry of ``values`` against the declarations ``params``.

    An undeclared key is an error naming the known ones.  Returns the checked values (SI), only for the
    keys given.
    """
    declared = {p.name: p for p in params}
    out = {}
    for key, value in values.items():
        if key not in declared:
            known = ", ".join(sorted(declared)) or "none"
            raise InputError(f"{where}: unknown parameter {key!r} (parameters: {known})")
        out[key] = check_value(declared[key], value, f"{where}: {key}")
    return out


def defaults(params: Iterable[Param]) -> dict[str, Any]:
    """``{name: default}`` of the declarations."""
    return {p.name: p.default for p in params}


def declared_values(params: Sequence[Param], values: Mapping[str, Any], where: str) -> dict[str, Any]:
    """Every declared parameter's value, in the declared order: ``values`` checked (:func:`check_values`: an
    undeclared key is refused by name) over the checked defaults."""
    return {**check_values(params, defaults(params), where), **check_values(params, values, where)}


def declared_factory(params: Sequence[Param], where: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Make a component's factory from its declaration, so its parameters are written once (the ``Param`` tuple).

    Decorates ``build(values, *, extra=default, ...)``, which receives every declared parameter's value in a dict
    (checked, converted to SI, defaults filled in: :func:`declared_values`) and any keyword-only extras of its own
    (a ``name``).  The factory takes the declared parameters positionally in the declared order or by keyword,
    with the declared defaults (its ``inspect.signature`` says so), then the extras by keyword.  A default that
    does not meet its own declaration is refused when the factory is made; an unknown keyword, a value given twice
    or too many positional values when it is called, each in one line naming ``where``.
    """
    params = tuple(params)
    names = tuple(p.name for p in params)
    check_values(params, defaults(params), f"{where} (declared defaults)")

    def wrap(build: Callable[..., Any]) -> Callable[..., Any]:
        extras = list(inspect.signature(build).parameters.values())[1:]
        clash = sorted({e.name for e in extras} & set(names))
        if clash or any(e.default is inspect.Parameter.empty for e in extras):
            raise ValueError(f"{where}: the build function's extras must have defaults and differ from the declared "
                             f"parameters (clash: {clash})")
        extra_names = {e.name for e in extras}

        @functools.wraps(build)
        def factory(*args: Any, **kwargs: Any) -> Any:
            if len(args) > len(names):
                raise InputError(f"{where}: takes at most {len(names)} positional values ({', '.join(names)}), got "
                                 f"{len(args)}")
            given = dict(zip(names, args))
            twice = sorted(set(given) & set(kwargs))
            if twice:
                raise InputError(f"{where}: {twice[0]!r} is given both by position and by keyword")
            extra = {k: kwargs.pop(k) for k in list(kwargs) if k in extra_names}
            return build(declared_values(params, {**given, **kwargs}, where), **extra)

        factory.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
            [inspect.Parameter(p.name, inspect.Parameter.POSITIONAL_OR_KEYWORD, default=p.default) for p in params]
            + [e.replace(kind=inspect.Parameter.KEYWORD_ONLY) for e in extras],
            return_annotation=inspect.signature(build).return_annotation)
        factory.parameters = params  # type: ignore[attr-defined]
        return factory

    return wrap


_PYTHON_TYPES = {"float": "float", "int": "int", "bool": "bool", "str": "str", "vector": "tuple[float, ...]",
                 "float?": "float | None", "vector?": "tuple[float, ...] | None"}


def declared_dataclass(name: str, params: Sequence[Param], module: str, bases: tuple[type, ...] = (),
                       doc: str | None = None) -> type:
    """A frozen dataclass whose fields are the declared parameters, in order, with their defaults (so a setting
    class does not write them a second time).  Methods, and a ``__post_init__`` that checks the values, come from
    ``bases``; ``module`` is the defining module's ``__name__`` (pickling finds the class there by ``name``)."""
    fields = [(p.name, _PYTHON_TYPES[p.type], dataclasses.field(default=p.default)) for p in params]
    cls = dataclasses.make_dataclass(name, fields, bases=bases, frozen=True)
    cls.__module__ = module  # make_dataclass's own module= is Python 3.12+
    if doc is not None:
        cls.__doc__ = doc
    return cls


def infer_params(values: Mapping[str, Any]) -> tuple[Param, ...]:
    """Declarations guessed from default values, for a third-party component that declares none.

    The type is read from each value; no unit and no range are assumed.
    """
    out = []
    for name, value in values.items():
        if isinstance(value, bool):
            kind = "bool"
        elif isinstance(value, int):
            kind = "int"
        elif isinstance(value, float):
            kind = "float"
        elif isinstance(value, str):
            kind = "str"
        elif value is None:
            kind = "float?"
        elif isinstance(value, (list, tuple)) and all(isinstance(v, (int, float)) for v in value):
            kind = "vector"
        else:
            kind = "str"
        out.append(Param(name, value, "(not declared by the plugin)", kind))
    return tuple(out)


def format_value(value: Any) -> str:
    """A short, human-readable value: ``2000``, ``0.5``, ``(0.5, 0.5, 1, 1)``, ``none``."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (tuple, list)):
        return "(" + ", ".join(format_value(v) for v in value) + ")"
    return str(value)


def describe(params: Iterable[Param], values: Mapping[str, Any] | None = None) -> list[tuple[str, str, str, str, str]]:
    """Rows ``(name, type, unit, value, doc)`` for listings; ``values`` (default: the defaults) fills the
    value column."""
    rows = []
    for p in params:
        value = p.default if values is None or p.name not in values else values[p.name]
        bounds = ""
        if p.minimum is not None or p.maximum is not None or p.above is not None:
            lo = f"{p.above:g} < " if p.above is not None else "" if p.minimum is None else f"{p.minimum:g} <= "
            hi = "" if p.maximum is None else f" <= {p.maximum:g}"
            bounds = f" [{lo}x{hi}]"
        if p.choices:
            bounds = f" [{' | '.join(map(str, p.choices))}]"
        rows.append((p.name, p.type + bounds, p.unit_label or "-", format_value(value), p.doc))
    return rows


def split_list(text: str) -> list[str]:
    """Split a comma-separated list, keeping ``name(a=1, b=[2, 3], c="x,y")`` whole; entries are stripped and
    empty ones are kept (as ``""``) for the caller to refuse."""
    parts, depth, quote, current = [], 0, "", ""
    for ch in text:
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "([":
            depth += 1
        elif ch in ")]":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(current.strip())
            current = ""
            continue
        current += ch
    parts.append(current.strip())
    return parts


def parse_reference(text: str, where: str = "component") -> tuple[str, dict[str, Any]]:
    """Split a component reference ``"name"`` or ``"name(key=value, ...)"`` into the name and its raw values.

    Values are read as TOML values where they are one (``2000``, ``0.5``, ``true``, ``"iso"``, ``[1, 2]``) and kept
    as plain strings otherwise (``arc-length``, ``15 m/s``), for the component's declarations to check.  Commas
    inside brackets or quotes do not split.

    >>> parse_reference("sir(particles=2000, threshold=0.5)")
    ('sir', {'particles': 2000, 'threshold': 0.5})
    """
    text = text.strip()
    if "(" not in text:
        if not text or any(c in text for c in ")=,"):
            raise InputError(f"{where}: cannot read {text!r} as a component name")
        return text, {}
    if not text.endswith(")"):
        raise InputError(f"{where}: {text!r} must end with ')': write name(key=value, ...)")
    name, inner = text[: text.index("(")].strip(), text[text.index("(") + 1: -1]
    if not name:
        raise InputError(f"{where}: {text!r} has no component name before '('")
    parts = split_list(inner)
    if parts and not parts[-1]:  # a trailing comma: name(a=1, )
        parts.pop()
    values: dict[str, Any] = {}
    for part in parts:
        if "=" not in part:
            raise InputError(f"{where}: {part.strip()!r} in {text!r} is not key=value")
        key, raw = (s.strip() for s in part.split("=", 1))
        if not key.isidentifier():
            raise InputError(f"{where}: {key!r} in {text!r} is not a parameter name")
        if key in values:
            raise InputError(f"{where}: {key!r} is given twice in {text!r}")
        values[key] = _read_value(raw)
    return name, values


def _read_value(raw: str) -> Any:
    import sys

    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except Exception:  # noqa: BLE001 - not a TOML value: a bare string (a choice, or a quantity with a unit)
        return raw


def check_footprint(params: Iterable[Param], values: Mapping[str, Any], batch: int, dim: int, who: str,
                    share: float = 0.5) -> None:
    """Refuse a configuration whose declared working memory (:attr:`Param.footprint`) would exceed ``share`` of the
    machine's memory for ``batch`` items of state dimension ``dim``, naming the parameter and the GiB."""
    limit = share * memory_limit()
    for p in params:
        if p.footprint is None or values.get(p.name) is None:
            continue
        need = float(batch) * dim * float(values[p.name]) * p.footprint
        if need > limit:
            raise InputError(f"{who}: {p.name} = {values[p.name]:g} for {batch} runs needs about {need / 2**30:.3g} GiB; "
                             f"this machine allows {limit / 2**30:.3g} GiB (half its memory): ask for fewer")
