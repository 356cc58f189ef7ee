"""The API reference builds from the docstrings with warnings as errors (``mkdocs build --strict``), and it covers
the public API: every name of ``workbench.__all__``, the public modules, the hook specifications, the test kit and
the Stone Soup interoperability package, and every module ``docs/writing-a-plugin.md`` tells plugin authors to use.
It renders: no page shows a raw Sphinx role (``docs/griffe_roles.py`` turns them into cross-references), and the
parameter tables hold names, types and descriptions in their own columns.

Needs the ``docs`` extra (``pip install -e ".[docs]"``); without it the test is skipped and says so.
"""

import importlib.util
import inspect
import re
import subprocess
import sys
import warnings
from html import unescape
from pathlib import Path

import pytest

import workbench

ROOT = Path(__file__).parents[1]
NEEDED = ("mkdocs", "mkdocstrings", "mkdocstrings_handlers.python")


def _missing() -> list[str]:
    out = []
    for name in NEEDED:
        try:
            found = importlib.util.find_spec(name) is not None
        except ModuleNotFoundError:
            found = False
        if not found:
            out.append(name)
    return out


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    missing = _missing()
    if missing:
        reason = (f"API reference not built: {', '.join(missing)} not installed (pip install -e \".[docs]\" to build "
                  f"it with warnings as errors)")
        warnings.warn(reason)  # shown in pytest's warnings summary, so the skip is seen
        pytest.skip(reason)
    out = tmp_path_factory.mktemp("api-site")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file",
                           str(ROOT / "mkdocs.yml"), "--site-dir", str(out)], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    log = (done.stdout + done.stderr)[-6000:]
    assert done.returncode == 0, f"mkdocs build --strict failed (warnings are errors):\n{log}"
    return out


def _anchors(site: Path, page: str) -> set[str]:
    html = (site / "api" / page / "index.html").read_text(encoding="utf-8")
    return set(re.findall(r'id="(workbench[A-Za-z0-9_.]*)"', html))


@pytest.mark.slow  # one site build for the module: about 15 s on 2 shared cores
def test_the_reference_builds_strictly_and_documents_every_public_name(site):
    anchors = _anchors(site, "workbench")
    public = [n for n in workbench.__all__ if not n.startswith("__")]
    assert public, "workbench.__all__ names no public API"
    missing = [n for n in public if f"workbench.{n}" not in anchors]
    assert not missing, f"names of workbench.__all__ missing from the reference: {missing}"


@pytest.mark.slow  # one site build for the module: about 15 s on 2 shared cores
@pytest.mark.parametrize("page, module", [
    ("types", "workbench.types"), ("models", "workbench.models"), ("models", "workbench.frames"),
    ("params", "workbench.params"), ("params", "workbench.units"), ("references", "workbench.references"),
    ("specs", "workbench.specs"), ("tracking", "workbench.tracking"),
    ("metrics", "workbench.metrics"), ("metrics", "workbench.metrics.ospa"), ("criteria", "workbench.criteria"),
    ("tracks_io", "workbench.tracks_io"), ("recorded", "workbench.recorded.sonar"),
    ("recorded", "workbench.recorded.pcl"), ("hookspecs", "workbench.hookspecs"), ("testing", "workbench.testing"),
    ("interop", "workbench_interop.stonesoup_filters"), ("interop", "workbench_interop.stonesoup_export"),
    # the modules docs/writing-a-plugin.md tells plugin authors to use
    ("plugins", "workbench.plugins"), ("filtering", "workbench.filtering"), ("kalman_core", "workbench.kalman_core"),
    ("particle_core", "workbench.particle_core"), ("resampling", "workbench.resampling"),
    ("linalg", "workbench.linalg"), ("memory", "workbench.memory"), ("sensing", "workbench.sensing"),
    ("sensing", "workbench.sensing.radar"),
    ("sensing", "workbench.sensing.bistatic"), ("report", "workbench.report.engine"),
    ("tracking", "workbench.tracking.gate"), ("tracking", "workbench.tracking.assign"),
    ("tracking", "workbench.tracking.initiation"), ("testing", "workbench.testing.kit"),
    ("testing", "workbench.testing.sensors"), ("testing", "workbench.testing.clutter"),
    ("testing", "workbench.testing.motion"),
])
def test_each_public_module_is_documented_with_its_exports(site, page, module):
    mod = importlib.import_module(module)
    anchors = _anchors(site, page)
    assert module in anchors, f"{module} has no section on api/{page}"
    names = getattr(mod, "__all__", None) or [n for n in vars(mod) if n.startswith("workbench_")]
    documented = [n for n in names if f"{module}.{n}" in anchors]
    # a module's exports are documented, except constants without a docstring of their own
    undocumented = [n for n in names if f"{module}.{n}" not in anchors and callable(getattr(mod, n, None))]
    assert documented and not undocumented, f"{module}: callables missing from api/{page}: {undocumented}"


@pytest.mark.slow  # one site build for the module: about 15 s on 2 shared cores
def test_the_hook_specifications_and_the_kit_entry_point_are_there(site):
    hooks = _anchors(site, "hookspecs")
    for hook in ("workbench_filters", "workbench_sensors", "workbench_clutter_generators",
                 "workbench_clutter_removers", "workbench_report_recipes", "workbench_benchmarks"):
        assert f"workbench.hookspecs.{hook}" in hooks
    assert "workbench.testing.parametrize_with_checks" in _anchors(site, "testing")


# ---- the reference renders: no raw Sphinx roles, the plugin guide's modules, parameter tables ----------------------

RAW_ROLE = re.compile(r":(class|func|meth|data|attr|mod|exc):")


def _visible_text(html: str) -> str:
    """The text a reader sees: scripts and styles dropped, tags stripped, entities decoded."""
    html = re.sub(r"<(script|style)\b.*?</\1>", " ", html, flags=re.S | re.I)
    return unescape(re.sub(r"<[^>]+>", " ", html))


def _pages(site: Path) -> dict[str, str]:
    return {str(p.relative_to(site)): p.read_text(encoding="utf-8") for p in sorted(site.rglob("*.html"))}


@pytest.mark.slow  # one site build for the module: about 15 s on 2 shared cores
def test_no_rendered_page_shows_a_raw_sphinx_role(site):
    pages = _pages(site)
    assert any(name.startswith("api/") for name in pages), "the site has no API pages"
    shown = {}
    for name, html in pages.items():
        text = _visible_text(html)
        hits = [text[max(m.start() - 40, 0):m.end() + 40].strip() for m in RAW_ROLE.finditer(text)]
        if hits:
            shown[name] = hits[:3]
    assert not shown, f"raw Sphinx roles shown on rendered pages: {shown}"


@pytest.mark.slow  # one site build for the module: about 15 s on 2 shared cores
def test_a_role_becomes_a_link_to_the_page_of_its_target(site):
    # run's docstring says :class:`~workbench.specs.FilterSpec`; rendered, it is a link to the specs page
    section = _section(site, "tracking", "workbench.tracking.run")
    links = re.findall(r'<a class="autorefs[^"]*"[^>]*href="([^"]+)"[^>]*>\s*<code>FilterSpec</code>', section)
    assert "../specs/#workbench.specs.FilterSpec" in links, f"FilterSpec not linked from run: {links}"


def _guide_modules() -> list[str]:
    """The modules docs/writing-a-plugin.md names: the longest importable prefix of every ``workbench.a.b`` it
    writes, and the ``.name`` parts it writes relative to a package it names (``workbench.tracking`` + ``.assign``)."""
    guide = (ROOT / "docs" / "writing-a-plugin.md").read_text(encoding="utf-8")
    named = set(re.findall(r"`(workbench(?:\.[A-Za-z_]\w*)+)", guide))

    def importable(name: str) -> bool:
        try:
            importlib.import_module(name)
        except ImportError:
            return False
        return True

    modules = set()
    for name in named:
        parts = name.split(".")
        while len(parts) > 1 and not importable(".".join(parts)):
            parts.pop()
        if len(parts) > 1:
            modules.add(".".join(parts))
    packages = {m for m in modules if hasattr(importlib.import_module(m), "__path__")}
    for rel in re.findall(r"`\.([A-Za-z_]\w*)`", guide):
        modules.update(f"{p}.{rel}" for p in packages if importable(f"{p}.{rel}"))
    return sorted(modules)


@pytest.mark.slow  # one site build for the module: about 15 s on 2 shared cores
def test_every_module_the_plugin_guide_names_has_a_page_with_its_public_functions(site):
    modules = _guide_modules()
    # the ones the guide tells authors to share through the core are among them
    for core in ("workbench.filtering", "workbench.kalman_core", "workbench.particle_core", "workbench.resampling",
                 "workbench.linalg", "workbench.sensing", "workbench.tracking.assign"):
        assert core in modules, f"{core} not found in docs/writing-a-plugin.md"
    anchors = {page: set(re.findall(r'id="([A-Za-z_][\w.]*)"', html)) for page, html in _pages(site).items()
               if page.startswith("api/")}
    problems = []
    for module in modules:
        pages = [page for page, ids in anchors.items() if module in ids]
        if not pages:
            problems.append(f"{module}: no reference page")
            continue
        mod = importlib.import_module(module)
        public = getattr(mod, "__all__", None) or [n for n, v in vars(mod).items() if not n.startswith("_")
                                                   and getattr(v, "__module__", None) == module]
        functions = [n for n in public if callable(getattr(mod, n, None))]
        missing = [n for n in functions if f"{module}.{n}" not in anchors[pages[0]]]
        if missing:
            problems.append(f"{module}: {missing} not rendered on {pages[0]}")
    assert not problems, "modules of the plugin guide missing from the reference:\n" + "\n".join(problems)


def _section(site: Path, page: str, ident: str) -> str:
    """The rendered HTML of the object ``ident`` on api/``page``: from its heading to the next heading."""
    html = (site / "api" / page / "index.html").read_text(encoding="utf-8")
    start = html.find(f'id="{ident}"')
    assert start >= 0, f"{ident} not on api/{page}"
    end = html.find('class="doc doc-heading"', html.find("</h", start))
    return html[start:end if end > 0 else len(html)]


def _parameter_table(section: str) -> list[tuple[str, str, str]]:
    """(name, type, description) of each row of the first Parameters list of a rendered docstring."""
    start = section.find('<span class="doc-section-title">Parameters:</span>')
    assert start >= 0, "no Parameters section rendered"
    block = section[start:section.find("</ul>", start)]
    rows = []
    for item in re.findall(r'<li class="doc-section-item field-body">(.*?)</li>', block, flags=re.S):
        name = re.search(r"<b><code>(.*?)</code></b>", item, flags=re.S)
        kind = re.search(r"\(<code>(.*?)</code>", item, flags=re.S)
        desc = re.search(r'<div class="doc-md-description">(.*?)</div>', item, flags=re.S)
        rows.append(tuple(" ".join(_visible_text(m.group(1)).split()) if m else "" for m in (name, kind, desc)))
    return rows


@pytest.mark.slow  # one site build for the module: about 15 s on 2 shared cores
@pytest.mark.parametrize("page, ident, function", [
    ("tracking", "workbench.tracking.run", "workbench.tracking.run"),
    ("plugins", "workbench.plugins.load_host", "workbench.plugins.load_host"),
])
def test_parameter_tables_hold_names_types_and_descriptions_in_their_columns(site, page, ident, function):
    module, _, name = function.rpartition(".")
    signature = inspect.signature(getattr(importlib.import_module(module), name))
    rows = _parameter_table(_section(site, page, ident))
    assert [r[0] for r in rows] == list(signature.parameters), f"{ident}: parameter names {rows}"
    for pname, kind, desc in rows:
        # a description that lands in the type column leaves the description empty and the type a sentence
        assert desc, f"{ident}: parameter {pname!r} has no description (type column: {kind!r})"
        assert kind and len(kind.split()) <= 6 and not kind.lower().startswith(("the ", "a ", "an ")), \
            f"{ident}: parameter {pname!r} shows {kind!r} as its type"


def _documented_objects():
    """``(dotted name, object)`` of every public function, class and method of the ``workbench`` package."""
    import pkgutil

    names = ["workbench"] + [m.name for m in pkgutil.walk_packages(workbench.__path__, "workbench.")]
    for module_name in names:
        try:
            module = importlib.import_module(module_name)
        except ImportError:  # an optional backend (Taichi, Numba) missing here
            continue
        for name, value in vars(module).items():
            if name.startswith("_") or getattr(value, "__module__", None) != module_name:
                continue
            yield f"{module_name}.{name}", value
            if inspect.isclass(value):
                for member, fn in vars(value).items():
                    if not member.startswith("_") and callable(fn):
                        yield f"{module_name}.{name}.{member}", fn


_SECTION = re.compile(r"^(Parameters|Attributes|Returns|Other Parameters)\n-+\n(.*?)(?=\n\n[A-Z][A-Za-z ]+\n-+\n|\Z)",
                      re.S | re.M)


def test_every_numpydoc_item_keeps_its_description_out_of_the_type_column():
    """Without a site build: in every public docstring, each item line of a Parameters, Attributes or Returns
    section is ``name : type`` with a type, not a sentence (the renderer puts whatever follows `` : `` in the type
    column, so ``path : the file to write`` shows the description as a type and leaves the description empty)."""
    problems = []
    for ident, obj in _documented_objects():
        doc = inspect.getdoc(obj) or ""
        for section in _SECTION.finditer(doc):
            for line in section.group(2).splitlines():
                if not line or line.startswith(" "):
                    continue
                item = re.match(r"^([\w*]+(?:, [\w*]+)*)\s*:\s*(.*)$", line)
                if item is None:
                    continue
                kind = item.group(2).strip()
                if " : " not in line and not line.rstrip().endswith(" :"):
                    problems.append(f"{ident}: {line!r} (write 'name : type')")
                elif kind.lower().startswith(("the ", "a ", "an ")) or kind.endswith("."):
                    problems.append(f"{ident}: {line!r} (a sentence in the type column)")
    assert not problems, "\n".join(problems)


# ---- the Griffe extension (docs/griffe_roles.py) on a small package, without a site build ---------------------------

ROLES_PACKAGE = {
    "__init__.py": '"""The package; see :mod:`.other`."""\nfrom .mod import Thing\n\n__all__ = ["Thing"]\n',
    "other.py": '"""Another module."""\n',
    "mod.py": '''"""Holds :class:`Thing` and :func:`~pkg.mod.helper`."""

LIMIT = 3


class Thing:
    """A thing: :meth:`.go`, :meth:`Thing.go`, :mod:`.other`, :class:`numpy.ndarray`, :func:`the helper <pkg.mod.helper>`.

    Parameters
    ----------
    x : :class:`Thing` or None
        Another :class:`~pkg.mod.Thing`; ``:class:`Thing``` in double backticks stays as it is.
    """

    def go(self):
        """Go, then :py:func:`helper`."""


def helper():
    """:data:`LIMIT`, or :class:`Missing`."""
''',
}


def _roles_module():
    pytest.importorskip("griffe", reason="the docs extra (griffe) is not installed")
    spec = importlib.util.spec_from_file_location("griffe_roles_under_test", ROOT / "docs" / "griffe_roles.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_roles_extension_writes_each_role_as_a_cross_reference_or_as_code(tmp_path):
    roles = _roles_module()
    import griffe

    (tmp_path / "pkg").mkdir()
    for name, text in ROLES_PACKAGE.items():
        (tmp_path / "pkg" / name).write_text(text, encoding="utf-8")
    loader = griffe.GriffeLoader(extensions=griffe.load_extensions(roles.SphinxRoles()), search_paths=[tmp_path])
    pkg = loader.load("pkg")

    def ref(path, title):
        return f'<autoref identifier="{path}" optional>`{title}`</autoref>'

    assert pkg.docstring.value == f"The package; see {ref('pkg.other', 'other')}."
    assert pkg["mod"].docstring.value == f"Holds {ref('pkg.mod.Thing', 'Thing')} and {ref('pkg.mod.helper', 'helper')}."
    thing = pkg["mod.Thing"].docstring.value.splitlines()
    assert thing[0] == (f"A thing: {ref('pkg.mod.Thing.go', 'go')}, {ref('pkg.mod.Thing.go', 'Thing.go')}, "
                        f"{ref('pkg.other', 'other')}, `numpy.ndarray`, {ref('pkg.mod.helper', 'the helper')}.")
    # the type of a numpydoc item is shown as code in the type column: the role becomes its plain title
    assert thing[4] == "x : Thing or None"
    assert thing[5] == (f"    Another {ref('pkg.mod.Thing', 'Thing')}; ``:class:`Thing``` in double backticks "
                        f"stays as it is.")
    assert pkg["mod.Thing.go"].docstring.value == f"Go, then {ref('pkg.mod.helper', 'helper')}."
    # a name Griffe does not know is inline code, never a reference that could break the strict build
    assert pkg["mod.helper"].docstring.value == f"{ref('pkg.mod.LIMIT', 'LIMIT')}, or `Missing`."
    # the package re-exports Thing: a reference through the re-export points at the class where it is defined
    assert roles.resolve(pkg["other"], "pkg.Thing", loader.modules_collection) == "pkg.mod.Thing"
