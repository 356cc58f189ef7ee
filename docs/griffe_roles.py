"""A Griffe extension that turns the Sphinx roles of the docstrings into mkdocstrings cross-references.

The docstrings of the workbench write references the Sphinx way (``:class:`~workbench.types.Gaussian```,
``:func:`run```, ``:meth:`.at```, ``:mod:`.gate```...), which mkdocstrings does not read: rendered as they are, a
reader sees the raw role.  This extension rewrites every docstring of a loaded package once the package is
loaded (Griffe's ``on_package`` event), before mkdocstrings parses it:

- the role's target is resolved the way Sphinx does: a dotted absolute path is taken as it is; a bare or relative
  name (``Gaussian``, ``Track.innovations``, ``.gate``) is looked up in the scope of the documented object: its
  class, its module with the names the module imports, and the packages above it with their submodules;
- a target that Griffe finds becomes a cross-reference to its canonical path, written as the autorefs tag
  ``<autoref identifier="PATH" optional>`TITLE`</autoref>`` (what ``[`TITLE`][PATH]`` becomes): it links where the
  object is rendered on some page, and where it is rendered nowhere it falls back to inline code without a warning,
  so ``mkdocs build --strict`` never fails on a reference to an undocumented helper;
- a target Griffe does not know (``numpy.ndarray``, ``None``) is rendered as inline code.

The title follows Sphinx: ``~a.b.C`` shows ``C``, ``a.b.C`` shows ``a.b.C``, ``.gate`` shows ``gate``, and
``:class:`text <a.b.C>``` shows ``text``.  ````double backticks```` are Markdown inline code already and are left
as they are.  Loaded from ``mkdocs.yml`` (``plugins: mkdocstrings: handlers: python: options: extensions:``).
"""

from __future__ import annotations

import html
import re
from typing import Any

from griffe import Extension, Module, Object

__all__ = ["ROLE", "SphinxRoles", "rewrite"]

#: A Sphinx role of the Python domain: ``:class:`target```, ``:py:func:`~a.b```, ``:meth:`title <a.B.c>```.
ROLE = re.compile(r"(?<![\w`:]):(?:py:)?(?P<role>class|func|meth|data|attr|mod|exc|obj|const):`(?P<body>[^`\n]+)`")
_EXPLICIT = re.compile(r"^(?P<title>.*?)\s*<(?P<target>[^<>]+)>$")


def _lookup(collection: Any, path: str) -> Object | None:
    """The object at ``path`` in the modules collection, or None where there is none (or its alias is broken)."""
    try:
        return collection[path]
    except Exception:  # noqa: BLE001 - KeyError, AliasResolutionError, CyclicAliasError: the path is not there
        return None


def _canonical(found: Object) -> str:
    try:
        return found.canonical_path
    except Exception:  # noqa: BLE001 - an alias whose target is not loaded: keep the path it was found under
        return found.path


def resolve(obj: Object, target: str, collection: Any) -> str | None:
    """The canonical path ``target`` names in the docstring of ``obj``, or None where Griffe knows no such object."""
    relative = target.startswith(".")
    name = target.lstrip(".")
    if not name or not re.fullmatch(r"[A-Za-z_][\w.]*", name):
        return None
    head, _, rest = name.partition(".")
    candidates: list[str] = []
    if not relative:
        candidates.append(name)  # an absolute path, or a top-level package
    # the documented object's scope: its members, its class, its module (with what it imports), the packages above
    try:
        found = obj.resolve(head)
    except Exception:  # noqa: BLE001 - NameResolutionError: not a name in this scope
        found = None
    if found:
        candidates.append(f"{found}.{rest}" if rest else found)
    for path in candidates:
        hit = _lookup(collection, path)
        if hit is not None:
            return _canonical(hit)
    return None


def _title(body: str) -> tuple[str, str]:
    """(title, target) of a role's body, the way Sphinx shows it."""
    explicit = _EXPLICIT.match(body)
    if explicit and explicit["title"]:
        return explicit["title"], explicit["target"].strip()
    target = body.strip()
    if target.startswith("~"):
        target = target[1:]
        return target.lstrip(".").rsplit(".", 1)[-1], target
    return target.lstrip("."), target


#: numpydoc sections whose items start with a ``name : type`` (or a type) line: the type lands in the rendered
#: type column, as code, where a link cannot go
ITEM_SECTIONS = frozenset({"parameters", "other parameters", "type parameters", "returns", "yields", "receives",
                           "raises", "warns", "attributes", "functions", "methods", "classes", "type aliases",
                           "modules"})


def _is_dashes(line: str) -> bool:
    return "-" in line and not line.replace("-", "").strip()


def rewrite(text: str, obj: Object, collection: Any) -> str:
    """``text`` with each Sphinx role replaced by a cross-reference (or by inline code where none resolves).

    On the first line of an item of a numpydoc section (``name : type``) a role becomes its plain title: that text
    is shown as the type, already as code.
    """

    def linked(match: re.Match) -> str:
        title, target = _title(match["body"])
        path = resolve(obj, target, collection)
        code = f"`{title}`"
        if path is None:
            return code
        return f'<autoref identifier="{html.escape(path, quote=True)}" optional>{code}</autoref>'

    def plain(match: re.Match) -> str:
        return _title(match["body"])[0]

    lines = text.split("\n")
    in_items = False
    for i, line in enumerate(lines):
        top_level = bool(line.strip()) and not line.startswith((" ", "\t"))
        if top_level and i + 1 < len(lines) and _is_dashes(lines[i + 1]) and not _is_dashes(line):
            in_items = line.strip().lower() in ITEM_SECTIONS
            continue
        if in_items and top_level and not _is_dashes(line):
            lines[i] = ROLE.sub(plain, line)
        else:
            lines[i] = ROLE.sub(linked, line)
    return "\n".join(lines)


class SphinxRoles(Extension):
    """Rewrite the Sphinx roles of every docstring of a loaded package into mkdocstrings cross-references."""

    def on_package(self, *, pkg: Module, loader: Any, **kwargs: Any) -> None:
        collection = loader.modules_collection
        seen: set[int] = set()
        stack: list[Object] = [pkg]
        while stack:
            obj = stack.pop()
            if obj.is_alias or id(obj) in seen:
                continue
            seen.add(id(obj))
            if obj.docstring is not None and ROLE.search(obj.docstring.value):
                obj.docstring.value = rewrite(obj.docstring.value, obj, collection)
            stack.extend(member for member in obj.members.values() if not member.is_alias)
