"""The rules every list of component references follows, wherever it comes from.

A scenario file's ``[filters] names`` and the command line's ``--filters``, ``--paper`` and ``--block`` are held
to the same rules, checked here once so that the same mistake gets the same message from either route (only the
place named before the colon differs: ``s.toml: [filters] names[1]`` or ``--filters 'kf'``):

- the list names at least one entry (:func:`require_entries`);
- no entry is empty or unreadable (:func:`workbench.params.parse_reference`);
- a filter reference names an installed *filter*: a sensor's or a clutter plugin's name is refused as that kind
  (:meth:`workbench.plugins.PluginHost.filter`), and its values are checked against the filter's declarations;
- nothing is listed twice (:func:`refuse_repeats`): two filters are the same when they are the same filter with
  the same checked values, however they are spelled (``sir(particles=100)`` and ``sir( particles = 100 )``, or
  ``sir`` and ``sir`` configured with its own defaults).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

from .params import parse_reference, split_list
from .plugins import UnknownComponent
from .types import InputError

__all__ = ["FilterReference", "UnknownReference", "split_list", "require_entries", "refuse_repeats", "filter_reference",
           "filter_list", "FILTER_FORMS"]

#: How a filter list is written; the message for an empty list shows it.
FILTER_FORMS = "each a name such as 'kf' or a configured filter such as 'sir(particles=2000)'"


class UnknownReference(UnknownComponent, InputError):
    """A reference to a component that is not installed (or is of another kind), named where it was written:
    both an :class:`~workbench.plugins.UnknownComponent` and an :class:`~workbench.types.InputError`."""


@dataclass(frozen=True)
class FilterReference:
    """One checked filter reference.

    ``text`` is how it was written (a reference, or ``name(key=value, ...)`` made from a table); ``base`` the
    installed filter's name; ``changed`` the checked values that differ from its defaults; ``key`` the
    filter's canonical label (``base`` when nothing changed), which decides whether two entries are the same.
    """

    text: str
    base: str
    key: str
    changed: Mapping[str, Any] = field(default_factory=dict)


def require_entries(entries: Sequence, where: str, what: str, forms: str = "") -> None:
    """Refuse an empty list (or one whose entries are all blank) of ``what`` (``"filter"``, ``"paper"``...)."""
    if not any(e.strip() if isinstance(e, str) else True for e in entries):
        raise InputError(f"{where}: expected a non-empty list of {what}s" + (f" ({forms})" if forms else ""))


def refuse_repeats(entries: Iterable[tuple[str, str]], where: str, what: str) -> None:
    """Refuse a list that names one thing twice.  ``entries`` are ``(as written, key)`` pairs: two entries with
    one key are the same ``what``; the message names each repeated one as written (and the key where the
    spellings differ)."""
    spellings: dict[str, list[str]] = {}
    for text, key in entries:
        spellings.setdefault(key, []).append(text)
    repeated = [(key, texts) for key, texts in spellings.items() if len(texts) > 1]
    if not repeated:
        return
    shown = []
    for key, texts in repeated:
        distinct = list(dict.fromkeys(texts))
        if len(distinct) == 1:
            shown.append(repr(distinct[0]))
        else:
            shown.append(" and ".join(repr(t) for t in distinct) + f" ({'both' if len(distinct) == 2 else 'all'} {key})")
    raise InputError(f"{where}: the same {what} is listed twice: {'; '.join(shown)}")


def filter_reference(host, entry: str | Mapping, where: str) -> FilterReference:
    """One filter entry: a reference ``"name"`` / ``"name(key=value, ...)"`` or a table ``{name = ..., key =
    value}``, checked against the installed filters and their declarations; errors are prefixed by ``where``."""
    from .specs import configured_name

    if isinstance(entry, str) and not entry.strip():
        raise InputError(f"{where}: an empty entry where a filter belongs ({FILTER_FORMS})")
    if isinstance(entry, str):
        base, values = parse_reference(entry, where)
        text = entry.strip()
    elif isinstance(entry, Mapping) and isinstance(entry.get("name"), str):
        base, values = entry["name"], {k: v for k, v in entry.items() if k != "name"}
        text = configured_name(base, values)
    else:
        raise InputError(f"{where}: expected a filter name or a table with a 'name', got {entry!r}")
    try:
        spec = host.filter(base)
        configured = spec.configure(**values) if values else spec
    except UnknownComponent as exc:
        raise UnknownReference(f"{where}: {exc}") from None
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    changed = {k: configured.params[k] for k in values}
    return FilterReference(text, base, configured.name if values else base, changed)


def filter_list(host, entries: Sequence[str | Mapping], where: str, entry_where) -> list[FilterReference]:
    """A whole list of filters: non-empty, each entry checked (``entry_where(i, entry)`` names it in a message),
    none listed twice."""
    require_entries(entries, where, "filter", FILTER_FORMS)
    refs = [filter_reference(host, entry, entry_where(i, entry)) for i, entry in enumerate(entries)]
    refuse_repeats(((r.text, r.key) for r in refs), where, "filter")
    return refs
