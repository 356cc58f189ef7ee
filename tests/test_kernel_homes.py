"""Where compiled kernels live (issue 23, item 7): ``workbench/kernels/`` keeps what the core or several plugins use
(the backend policy, the runtime, the particle-filter and random-stream kernels); a kernel that serves one plugin
lives in that plugin's package (the CRPF step in ``workbench_filters.crpf``, the method-C weights in
``workbench_filters.tbd``, the UKF loops in ``workbench_filters.sigma_point``).

Checked on the source with ``ast``: every module of ``workbench/kernels/`` is imported by the core (a module of
``workbench/`` outside the kernels, directly or through kernel modules that the core imports) or by the modules of
at least two plugins (a plugin: one entry point's module or package, e.g. ``workbench_filters.crpf``,
``workbench_papers.paper000``), tests excepted.
"""

import ast
import functools
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
KERNELS = ROOT / "workbench" / "kernels"
#: Plugin package -> its folder (as pyproject.toml maps them).
PLUGIN_FOLDERS = {"workbench_filters": "plugins/filters", "workbench_sensors": "plugins/sensors",
                  "workbench_clutter": "plugins/clutter", "workbench_papers": "plugins/papers",
                  "workbench_interop": "plugins/interop", "workbench_motion": "plugins/motion",
                  "workbench_trackers": "plugins/trackers"}
#: Core services kept in the core by design while fewer than two plugins use them yet, each with its reason.  An
#: entry that becomes unnecessary (the module gains a second user) or names no module fails the test below.
CORE_BY_DESIGN = {
    "counter_normals": "the random-stream kernel: counter-based normals, a pure function of (key, row), that any "
                       "particle filter may draw from (issue 23 keeps the random-stream kernels in the core)",
    "counter_normals_numba": "the compiled twin of counter_normals",
    "counter_normals_numpy": "the NumPy twin of counter_normals",
}


def sources(root: Path = ROOT) -> dict[Path, str]:
    """The text of every Python file of the core and of the plugins (tests excepted), by path from ``root``."""
    out = {}
    for top in ("workbench", *PLUGIN_FOLDERS.values()):
        for path in sorted((root / top).rglob("*.py")):
            rel = path.relative_to(root)
            if "tests" not in rel.parts and "__pycache__" not in rel.parts:
                out[rel] = path.read_text(encoding="utf-8")
    return out


def _module_name(rel: Path) -> tuple[str, bool]:
    """A source file's module name (``plugins/filters/crpf/__init__.py`` -> ``workbench_filters.crpf``) and whether
    it is a package."""
    parts = list(rel.with_suffix("").parts)
    if parts[0] == "workbench":
        package, parts = "workbench", parts[1:]
    else:
        folder = "/".join(parts[:2])
        package = next(k for k, v in PLUGIN_FOLDERS.items() if v == folder)
        parts = parts[2:]
    is_package = parts[-1] == "__init__" if parts else True
    return ".".join([package, *(parts[:-1] if is_package else parts)]), is_package


@functools.lru_cache(maxsize=None)
def _parse(text: str) -> ast.Module:
    return ast.parse(text)


def _imported_modules(text: str, module: str, is_package: bool) -> set[str]:
    """Every module an import statement of the file names, relative imports resolved (``module``: the file's own
    module name), at module level or inside a function; ``from a import b`` names both ``a`` and ``a.b``."""
    out = set()
    here = module.split(".") if is_package else module.split(".")[:-1]
    for node in ast.walk(_parse(text)):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = here[:len(here) - node.level + 1] if node.level else []
            name = ".".join(base + ([node.module] if node.module else []))
            out |= {name} | {f"{name}.{a.name}" for a in node.names}
    return out


def kernel_users(files: dict[Path, str] | None = None) -> dict[str, set[str]]:
    """Kernel module -> its users: ``"core"`` and plugin names (``workbench_filters.crpf``: a plugin's top-level
    module or package), following imports between kernel modules."""
    files = sources() if files is None else files
    kernel_dir = Path("workbench/kernels")
    kernels = {rel.stem for rel in files if rel.parent == kernel_dir and rel.stem != "__init__"}
    users: dict[str, set[str]] = {k: set() for k in kernels}
    importers: dict[str, set[str]] = {k: set() for k in kernels}  # kernel -> the kernels that import it
    for rel, text in files.items():
        if rel.parent != kernel_dir and "kernels" not in text:
            continue  # names no kernel module (a sound filter: every import of one outside the kernels says so)
        module, is_package = _module_name(rel)
        used = {m.split(".")[2] for m in _imported_modules(text, module, is_package)
                if m.startswith("workbench.kernels.") and m.split(".")[2] in kernels}
        for k in used - {rel.stem}:
            if rel.parent == kernel_dir:
                importers[k].add(rel.stem)
            elif rel.parts[0] == "workbench":
                users[k].add("core")
            else:
                users[k].add(module.split(".")[0] + "." + rel.parts[2].removesuffix(".py"))
    changed = True
    while changed:  # a kernel serves whoever the kernels importing it serve
        changed = False
        for k, by in importers.items():
            for imp in by:
                if not users[imp] <= users[k]:
                    users[k] |= users[imp]
                    changed = True
    return users


def single_plugin_kernels(files: dict[Path, str] | None = None) -> dict[str, set[str]]:
    """The core's kernel modules that neither the core nor two plugins use (the design exemptions aside)."""
    return {k: u for k, u in kernel_users(files).items()
            if "core" not in u and len(u) < 2 and k not in CORE_BY_DESIGN}


def test_every_core_kernel_serves_the_core_or_several_plugins():
    found = single_plugin_kernels()
    assert not found, ("kernels in workbench/kernels/ that serve one plugin only (move them into that plugin's "
                       "package): " + ", ".join(f"{k} (used by {sorted(u) or 'nothing'})" for k, u in found.items()))


def test_the_design_exemptions_are_needed_and_name_real_modules():
    users = kernel_users()
    for name, reason in CORE_BY_DESIGN.items():
        assert name in users, f"CORE_BY_DESIGN names {name}, which is not in workbench/kernels/"
        assert reason
        assert "core" not in users[name] and len(users[name]) < 2, \
            f"{name} is now used by {sorted(users[name])}: drop it from CORE_BY_DESIGN"


def test_the_shared_kernels_are_seen_as_shared():
    users = kernel_users()
    # the bootstrap filter's kernels: the core (particle_core) and the CRPF's step (its atan2)
    assert "core" in users["particle_numba"] and "workbench_filters.crpf" in users["particle_numba"]
    assert "core" in users["atan_poly"] and "core" in users["backend"] and "core" in users["vector_width"]
    for moved in ("crpf_step", "crpf_step_numpy", "crpf_numba", "crpf_taichi", "tbd_weights", "tbd_weights_numba",
                  "tbd_weights_numpy", "tbd_weights_taichi", "reference", "sigma_numba"):
        assert moved not in users, f"{moved} is back in workbench/kernels/"


def test_a_single_plugin_kernel_put_back_in_the_core_is_caught():
    files = sources()
    assert single_plugin_kernels(files) == {}
    # the CRPF's dispatcher put back in the core, imported by the crpf plugin only
    files[Path("workbench/kernels/crpf_step.py")] = "import numpy as np\n\nSTEP = 1\n"
    crpf = Path("plugins/filters/crpf/__init__.py")
    files[crpf] = "from workbench.kernels.crpf_step import STEP\n" + files[crpf]
    assert single_plugin_kernels(files) == {"crpf_step": {"workbench_filters.crpf"}}
    # a second module of the same plugin does not make it shared
    files[Path("plugins/filters/crpf/bench.py")] += "\nfrom workbench.kernels import crpf_step\n"
    assert single_plugin_kernels(files) == {"crpf_step": {"workbench_filters.crpf"}}
    # used through a kernel the core imports (a relative import between kernels), or by the core itself, it is shared
    shared = dict(files)
    shared[Path("workbench/kernels/runtime.py")] += "\nfrom . import crpf_step\n"
    assert single_plugin_kernels(shared) == {}
    shared = dict(files)
    shared[Path("workbench/noise.py")] = "from .kernels.crpf_step import STEP\n"
    assert single_plugin_kernels(shared) == {}


def test_a_kernel_no_one_imports_is_caught():
    files = sources()
    files[Path("workbench/kernels/orphan_numba.py")] = "X = 1\n"
    assert single_plugin_kernels(files) == {"orphan_numba": set()}
