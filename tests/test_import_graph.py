"""No two modules of the workbench package (or of the built-in plugin packages) import each other.

Every module is parsed with :mod:`ast` (nothing is imported) and every import statement in it is collected, at
module level and inside functions alike (a lazy import is still a circle: it only hides it), relative and absolute.
An import names the module it reads: ``from .loop import run`` is ``loop``; ``from . import reading`` is
``reading`` where that is a module, else the package; ``from ..tracking import Direct`` is the package
``tracking`` (its ``__init__``).  Two modules that import each other are reported by name.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _module_name(path: Path, base: Path) -> str:
    parts = list(path.relative_to(base).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def import_graph(package: Path, base: Path) -> dict[str, set[str]]:
    """``module -> the modules of the same tree it imports``, for every ``.py`` file under ``package`` (tests
    folders left out), the names dotted from ``base``."""
    modules = {_module_name(p, base): p for p in sorted(package.rglob("*.py"))
               if "tests" not in p.relative_to(package).parts}

    def owner(name: str) -> str | None:
        """The longest module of the tree that ``name`` lies in (``a.b.c`` -> ``a.b`` when ``c`` is a name)."""
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        package_of = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets: set[str] = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                targets.update(filter(None, (owner(a.name) for a in node.names)))
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    parts = package_of.split(".")
                    parts = parts[:len(parts) - (node.level - 1)]
                    source = ".".join(parts + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                for alias in node.names:
                    full = f"{source}.{alias.name}"
                    targets.update(filter(None, (owner(full if full in modules else source),)))
        targets.discard(name)
        graph[name] = targets
    return graph


def two_cycles(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """The pairs of modules that import each other, each pair once, sorted."""
    return sorted({tuple(sorted((a, b))) for a, targets in graph.items() for b in targets
                   if a in graph.get(b, ())})


@pytest.mark.parametrize("package", ["workbench", "plugins"])
def test_no_two_modules_import_each_other(package):
    graph = import_graph(ROOT / package, ROOT)
    assert len(graph) > 10  # the tree was found and read
    circles = two_cycles(graph)
    assert not circles, "modules that import each other: " + "; ".join(f"{a} <-> {b}" for a, b in circles)


def test_the_graph_sees_lazy_relative_and_absolute_imports(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from .a import f\n")
    (pkg / "a.py").write_text("def f():\n    from .b import g  # lazy, relative\n    return g\n")
    (pkg / "b.py").write_text("import pkg.a\n\ng = 1\n")  # absolute, module level
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "c.py").write_text("from .. import b\nfrom ..a import f\n")
    (pkg / "sub" / "d.py").write_text("if True:\n    from . import c\n")
    (pkg / "sub" / "e.py").write_text("from pkg.sub import d\nfrom .d import c\n")  # the name c, read from d
    graph = import_graph(pkg, tmp_path)
    assert graph == {"pkg": {"pkg.a"}, "pkg.a": {"pkg.b"}, "pkg.b": {"pkg.a"}, "pkg.sub": set(),
                     "pkg.sub.c": {"pkg.b", "pkg.a"}, "pkg.sub.d": {"pkg.sub.c"}, "pkg.sub.e": {"pkg.sub.d"}}
    assert two_cycles(graph) == [("pkg.a", "pkg.b")]
    (pkg / "sub" / "c.py").write_text("def h():\n    import pkg.sub.e as e\n    return e\n")
    (pkg / "sub" / "e.py").write_text("from ..sub.c import h\n")
    assert two_cycles(import_graph(pkg, tmp_path)) == [("pkg.a", "pkg.b"), ("pkg.sub.c", "pkg.sub.e")]
